"""The docs: the user guide and API reference build with warnings as errors, and the
tutorial notebook runs from top to bottom (at its tiny size)."""

from __future__ import annotations

import collections
import importlib
import json
import os
import pkgutil
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
NOTEBOOK = REPO / "docs" / "guide" / "tutorial.ipynb"


def test_the_docs_build_with_warnings_as_errors(tmp_path):
    pytest.importorskip("mkdocstrings")
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "mkdocs",
            "build",
            "--strict",
            "-f",
            str(REPO / "docs" / "mkdocs.yml"),
            "--site-dir",
            str(tmp_path / "site"),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert out.returncode == 0, out.stderr[-4000:]
    assert (tmp_path / "site" / "api" / "core" / "index.html").exists()
    assert "make_env" in (tmp_path / "site" / "api" / "core" / "index.html").read_text()
    html = "".join(p.read_text() for p in (tmp_path / "site").rglob("*.html"))
    roles = re.findall(r":(?:func|class|mod|data|meth|attr|obj|exc):`[^`]*`", html)
    assert not roles, roles[:10]  # Sphinx roles reach the page as links or code, never raw
    headings = collections.Counter(
        re.findall(r'id="(ntq_jax\.[A-Za-z0-9_.]+)"[^>]*class="doc doc-heading"', html)
    )
    counts = {f"{mod}.{name}": _documented(headings, mod, name) for mod, name in _public_names()}
    assert len(counts) > 100
    assert not {k: n for k, n in counts.items() if n != 1}  # every public name exactly once


def _public_names():
    """``(subpackage, name)`` for every name in the ``__all__`` of ``ntq_jax`` and of each
    of its subpackages (``__version__`` aside)."""
    import ntq_jax

    mods = ["ntq_jax"] + [
        f"ntq_jax.{m.name}" for m in pkgutil.iter_modules(ntq_jax.__path__) if m.ispkg
    ]
    for mod in mods:
        for name in getattr(importlib.import_module(mod), "__all__", ()):
            if not name.startswith("__"):
                yield mod, name


def _documented(headings: collections.Counter, mod: str, name: str) -> int:
    """How many reference entries document ``mod.name``: those at the path it is defined
    under (functions and classes), else any entry of that name (constants)."""
    obj = getattr(importlib.import_module(mod), name)
    where = getattr(obj, "__module__", None)
    if callable(obj) and isinstance(where, str) and where.startswith("ntq_jax"):
        return headings[f"{where}.{obj.__qualname__}"]
    return sum(n for path, n in headings.items() if path.endswith(f".{name}"))


def test_every_guide_page_is_in_the_navigation():
    nav = (REPO / "docs" / "mkdocs.yml").read_text()
    pages = {
        str(p.relative_to(REPO / "docs" / "guide")) for p in (REPO / "docs" / "guide").rglob("*.md")
    }
    assert pages and all(p in nav for p in pages), sorted(p for p in pages if p not in nav)


def test_the_tutorial_notebook_runs(tmp_path):
    """Every code cell, in order, in one fresh interpreter (as a kernel would), tiny size."""
    cells = json.loads(NOTEBOOK.read_text())["cells"]
    code = [("".join(c["source"])) for c in cells if c["cell_type"] == "code"]
    assert len(code) >= 6
    script = tmp_path / "tutorial.py"
    script.write_text("\n\n".join(code) + "\n\nprint('TUTORIAL DONE')\n")
    env = {**os.environ, "NTQ_TUTORIAL_TINY": "1", "MPLBACKEND": "Agg"}
    out = subprocess.run(
        [sys.executable, str(script)],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert out.returncode == 0 and "TUTORIAL DONE" in out.stdout, out.stderr[-4000:]
    for figure in ("datasets.png", "one_query.png"):
        assert (tmp_path / "tutorial_run" / figure).stat().st_size > 1000
    assert "gamma_nt = " in out.stdout and "PNet_3: solved" in out.stdout
    # issue 52: a member that finished early is not printed as a NaN loss; the figures are
    # shown (their paths in plain Python); the closing command names the map's real path
    assert "PNet_0: validation loss " in out.stdout and "nan" not in out.stdout.lower()
    assert (
        str(tmp_path / "tutorial_run" / "one_query.png") in out.stdout
        or "tutorial_run/one_query.png" in out.stdout
    )
    assert f"envs=[{(tmp_path / 'tutorial_run' / 'two_rooms.json').resolve()}]" in out.stdout
