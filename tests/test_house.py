"""The shape of the house: two layers with arrows one way, small modules, short functions.

* the core (every module of ``ntq_jax`` outside ``ntq_jax.experiment``) never
  imports the experiment layer;
* no module of ``ntq_jax``, ``scripts`` or ``benchmarks`` is over 500 lines, and no
  function of theirs has over 60 lines of code (docstring, blank and comment
  lines aside);
* no script or benchmark edits ``sys.path`` (they run against the installed package).
* the suite hands its files to the xdist workers heaviest first.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
PACKAGE = REPO / "ntq_jax"
MAX_MODULE_LINES = 500
MAX_FUNCTION_LINES = 60


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


def _code_lines(fn: ast.AST, lines: list[str]) -> int:
    body = fn.body
    first = body[0]
    if (isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant)
            and isinstance(first.value.value, str)):
        if len(body) == 1:
            return 0
        first = body[1]
    text = lines[first.lineno - 1: fn.end_lineno]
    return sum(1 for t in text if t.strip() and not t.strip().startswith("#"))


def test_the_core_never_imports_the_experiment_layer():
    back = []
    for f in _files("ntq_jax"):
        if "experiment" in f.relative_to(PACKAGE).parts:
            continue
        names = _imported(ast.parse(f.read_text(encoding="utf-8")))
        back += [f"{f.relative_to(REPO)} imports {n}" for n in sorted(names)
                 if n == "ntq_jax.experiment" or n.startswith("ntq_jax.experiment.")]
    assert not back, "\n".join(back)


def test_the_layers_are_where_the_docs_say():
    experiment = {p.stem for p in (PACKAGE / "experiment").glob("*.py")}
    assert {"config", "pipeline", "evaluate", "report", "summaries", "reproduction", "curve",
            "cli"} <= experiment
    assert not any((PACKAGE / f"{m}.py").exists() for m in experiment if m != "__init__")


@pytest.mark.parametrize("folder", ["ntq_jax", "scripts", "benchmarks"])
def test_no_module_is_over_500_lines(folder):
    big = [f"{f.relative_to(REPO)}: {n} lines" for f in _files(folder)
           if (n := len(f.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES]
    assert not big, "\n".join(big)


@pytest.mark.parametrize("folder", ["ntq_jax", "scripts", "benchmarks"])
def test_no_function_is_over_60_lines_of_code(folder):
    long = []
    for f in _files(folder):
        text = f.read_text(encoding="utf-8")
        lines = text.splitlines()
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                if (n := _code_lines(node, lines)) > MAX_FUNCTION_LINES:
                    long.append(f"{f.relative_to(REPO)}:{node.lineno} {node.name}: {n} lines")
    assert not long, "\n".join(long)


@pytest.mark.parametrize("folder", ["scripts", "benchmarks"])
def test_no_script_edits_sys_path(folder):
    edit = re.compile(r"sys\.path\s*(\.(insert|append|extend)\b|\[.*\]\s*=|\+?=)")
    edits = [str(f.relative_to(REPO)) for f in _files(folder)
             if edit.search(f.read_text(encoding="utf-8"))]
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
    assert [i.nodeid for i in items] == ["tests/b.py::z", "tests/b.py::v", "tests/a.py::x",
                                         "tests/a.py::w", "tests/new.py::y"]
