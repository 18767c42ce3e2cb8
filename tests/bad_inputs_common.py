"""Helpers shared by the hostile-input tests (tests/test_bad_inputs_*.py): listings of
folders, the one ``error:`` line, the tiny run's settings and its fixtures."""

from __future__ import annotations

import os
from pathlib import Path

from conftest import TINY_RUN
from script_loader import load_script

ROOT = Path(__file__).resolve().parents[1]


def _script(name):
    return load_script(name, f"_bad_inputs_{name}")


def _listing(root: Path) -> dict:
    """``{relative path: (is dir, size, mtime_ns)}`` of everything under ``root`` (and root)."""
    root = Path(root)
    if not root.exists():
        return {}
    out = {".": (root.is_dir(), root.stat().st_size if root.is_file() else 0, 0)}
    if root.is_dir():
        for p in sorted(root.rglob("*")):
            st = p.stat()
            out[str(p.relative_to(root))] = (
                p.is_dir(),
                0 if p.is_dir() else st.st_size,
                st.st_mtime_ns,
            )
    return out


def _one_error_line(err: str, status_lines: int = 0) -> str:
    """The one ``error:`` line ending stderr (after ``status_lines`` lines of progress)."""
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 + status_lines, err
    assert lines[-1].startswith("error: ") and "Traceback" not in err, err
    return lines[-1]


TINY = TINY_RUN  # the suite's tiny point/2 run (conftest.py)


def _files(folder: Path) -> set:
    return {p.relative_to(folder) for p in folder.rglob("*")}


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + [p for p in [env.get("PYTHONPATH")] if p])
    env.setdefault("JAX_PLATFORMS", "cpu")
    return env
