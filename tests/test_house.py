"""The shape of the house: two layers with arrows one way, small modules, short functions.

* the core (every module of ``ntq_jax`` outside ``ntq_jax.experiment``) never
  imports the experiment layer;
* a module holds one concept: over 500 lines is a warning (look for a second
  concept to split out; never pack statements or trim docstrings to stay under it),
  over 800 a failure, for ``ntq_jax``, ``scripts`` and ``benchmarks``;
* no function of theirs has over 60 statements (every statement of its body,
  nested ones included, its docstring aside): statements, not lines, so packing
  two onto one line gains nothing;
* no script or benchmark edits ``sys.path`` (they run against the installed package);
* the tree passes ruff's lint and format check (the settings in ``pyproject.toml``).
* the suite hands its files to the xdist workers heaviest first.
"""

from __future__ import annotations

import ast
import re
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
PACKAGE = REPO / "ntq_jax"
SOFT_MODULE_LINES = 500
MAX_MODULE_LINES = 800
MAX_FUNCTION_STATEMENTS = 60


def _files(*folders: str) -> list[Path]:
    return sorted(p for f in folders for p in (REPO / f).rglob("*.py"))


def _imported(tree: ast.AST) -> set[str]:
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module)
            out.update(f"{node.module}.{a.name}" for a in node.names)
    return out


def _statements(fn: ast.AST) -> int:
    """The statements of a function's body, nested ones included, its docstring aside."""
    body = fn.body
    first = body[0]
    doc = (
        isinstance(first, ast.Expr)
        and isinstance(first.value, ast.Constant)
        and isinstance(first.value.value, str)
    )
    return sum(1 for node in ast.walk(fn) if isinstance(node, ast.stmt) and node is not fn) - doc


def test_the_core_never_imports_the_experiment_layer():
    back = []
    for f in _files("ntq_jax"):
        if "experiment" in f.relative_to(PACKAGE).parts:
            continue
        names = _imported(ast.parse(f.read_text(encoding="utf-8")))
        back += [
            f"{f.relative_to(REPO)} imports {n}"
            for n in sorted(names)
            if n == "ntq_jax.experiment" or n.startswith("ntq_jax.experiment.")
        ]
    assert not back, "\n".join(back)


def test_the_layers_are_where_the_docs_say():
    experiment = {p.stem for p in (PACKAGE / "experiment").glob("*.py")}
    assert {
        "config",
        "pipeline",
        "evaluate",
        "report",
        "summaries",
        "reproduction",
        "curve",
        "cli",
    } <= experiment
    assert not any((PACKAGE / f"{m}.py").exists() for m in experiment if m != "__init__")


@pytest.mark.parametrize("folder", ["ntq_jax", "scripts", "benchmarks"])
def test_no_module_is_over_800_lines(folder):
    sizes = {
        f"{f.relative_to(REPO)}": len(f.read_text(encoding="utf-8").splitlines())
        for f in _files(folder)
    }
    for name, n in sizes.items():
        if SOFT_MODULE_LINES < n <= MAX_MODULE_LINES:
            warnings.warn(f"{name}: {n} lines: does it hold a second concept to split out?")
    big = [f"{name}: {n} lines" for name, n in sizes.items() if n > MAX_MODULE_LINES]
    assert not big, "\n".join(big)


@pytest.mark.parametrize("folder", ["ntq_jax", "scripts", "benchmarks"])
def test_no_function_is_over_60_statements(folder):
    long = []
    for f in _files(folder):
        for node in ast.walk(ast.parse(f.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                if (n := _statements(node)) > MAX_FUNCTION_STATEMENTS:
                    long.append(f"{f.relative_to(REPO)}:{node.lineno} {node.name}: {n} statements")
    assert not long, "\n".join(long)


def test_statements_not_lines_are_counted():
    packed = ast.parse('def f():\n    """Doc."""\n    a = 1; b = 2\n    if a:\n        c = 3\n')
    assert _statements(packed.body[0]) == 4  # two on one line, the if and the one inside it


@pytest.mark.parametrize("folder", ["scripts", "benchmarks"])
def test_no_script_edits_sys_path(folder):
    edit = re.compile(r"sys\.path\s*(\.(insert|append|extend)\b|\[.*\]\s*=|\+?=)")
    edits = [
        str(f.relative_to(REPO))
        for f in _files(folder)
        if edit.search(f.read_text(encoding="utf-8"))
    ]
    assert not edits, edits


def test_the_suite_hands_out_the_heaviest_files_first(tmp_path, monkeypatch):
    """``conftest.pytest_collection_modifyitems``: files in the order of
    ``tests/file_weights.json`` (heaviest first), unknown files after them, each file's tests
    in their own order; every test file of the suite has a weight."""
    import json
    from types import SimpleNamespace

    import conftest

    weights = json.loads(conftest.FILE_WEIGHTS.read_text())
    files = {f"tests/{p.name}" for p in (REPO / "tests").glob("test_*.py")}
    assert files <= set(weights), sorted(files - set(weights))
    w = tmp_path / "weights.json"
    w.write_text(json.dumps({"tests/a.py": 1.0, "tests/b.py": 9.0}))
    monkeypatch.setattr(conftest, "FILE_WEIGHTS", w)
    ids = ["tests/a.py::x", "tests/new.py::y", "tests/b.py::z", "tests/a.py::w", "tests/b.py::v"]
    items = [SimpleNamespace(nodeid=i) for i in ids]
    conftest.pytest_collection_modifyitems(None, None, items)
    assert [i.nodeid for i in items] == [
        "tests/b.py::z",
        "tests/b.py::v",
        "tests/a.py::x",
        "tests/a.py::w",
        "tests/new.py::y",
    ]


@pytest.mark.parametrize("mode", ["check", "format"])
def test_the_tree_passes_ruff(mode):
    pytest.importorskip("ruff")  # in the test extra
    args = ["check", "--no-cache"] if mode == "check" else ["format", "--check", "--no-cache"]
    out = subprocess.run(
        [sys.executable, "-m", "ruff", *args, "ntq_jax", "scripts", "benchmarks", "tests", "docs"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, (out.stdout + out.stderr)[-4000:]
