"""The factor study's section of REPRODUCTION.md (ntq_jax.experiment.factor_table)."""

from __future__ import annotations

import json

import pytest

from ntq_jax.experiment import factor_table as F
from ntq_jax.experiment import reproduction as R


def _row(model, kind, steer, band, diff, p, base=0.5, n=100):
    return {
        "model": model,
        "baseline": "PNet_0",
        "query_kind": kind,
        "steer": steer,
        "band": band,
        "n": n,
        "success": base + diff,
        "baseline_success": base,
        "success_diff": diff,
        "success_diff_ci95": [diff - 0.05, diff + 0.05],
        "mcnemar_p": p,
    }


def _cell(root, map_, data, budget, seed, nt_diff, nt_p):
    rows = [_row("PNet_3", "nontrivial", True, b, nt_diff, nt_p) for b in F.BANDS]
    rows += [
        _row("PNet_3", "nontrivial", False, "all", -0.01, 0.9, base=0.06),
        _row("PNet_3", "uniform", True, "all", 0.002, 0.95),
        _row("PNet_2", "nontrivial", True, "all", 0.3, 1e-6),
    ]  # in the decomposition only
    folder = root / map_.replace("/", "_") / data / budget
    if seed:
        folder = folder / "seeds" / f"train_seed_{seed}"
    folder.mkdir(parents=True)
    cell = {"map": map_, "data": data, "budget": budget, "train_seed": seed}
    (folder / "paired.json").write_text(json.dumps({"cell": cell, "sets": [], "paired": rows}))


def test_sign_of_needs_significance():
    assert F.sign_of(_row("PNet_3", "nontrivial", True, "all", -0.1, 0.001)) == "-"
    assert F.sign_of(_row("PNet_3", "nontrivial", True, "all", +0.1, 0.01)) == "+"
    assert F.sign_of(_row("PNet_3", "nontrivial", True, "all", -0.1, 0.05)) == "0"
    assert F.sign_of(None) == "?"


def test_q_values_are_benjamini_hochberg_over_the_whole_study(tmp_path):
    """Every comparison of every cell gets its BH q over all of them; the verdicts use q."""
    from ntq_jax.stats import benjamini_hochberg

    _cell(tmp_path, "rigid/0", "shortcut", "ours", 0, -0.114, 2e-5)
    _cell(tmp_path, "rigid/0", "bitstar", "ours", 0, +0.080, 0.03)
    cells = F.load_cells(tmp_path)
    rows = [r for c in cells for r in c["paired"]]
    assert [r["q"] for r in rows] == pytest.approx(
        list(benjamini_hochberg([r["mcnemar_p"] for r in rows]))
    )
    r = F._find(cells[0], "nontrivial", "all")  # bitstar: p 0.03, 8th of 12: q 0.03 x 12 / 8
    assert r["mcnemar_p"] == 0.03 and r["q"] == pytest.approx(0.045)
    assert F.sign_of(r) == "+" and F.sign_of({**r, "q": 0.06}) == "0"


def test_section_lists_each_cell_and_the_verdicts_per_factor(tmp_path):
    assert F.section(tmp_path) == []  # no cell: no section
    _cell(tmp_path, "rigid/0", "shortcut", "ours", 0, -0.114, 2e-5)
    _cell(tmp_path, "rigid/0", "bitstar", "ours", 0, +0.080, 0.002)
    _cell(tmp_path, "rigid/0", "bitstar", "ours", 1, +0.020, 0.4)
    lines = F.section(tmp_path)
    text = "\n".join(lines)
    assert lines[0] == "## What decides PNet_3 vs PNet_0"
    first = lines.index(
        "| map | data paths | budgets | seed | PNet_0 | non-trivial | in band "
        "| out of band | without steerTo | uniform |"
    )
    rows = lines[first + 2 : lines.index("", first)]  # the first table (the decomposition follows)
    # sorted by map, data paths, budgets, seed; PNet_0 with / without steerTo
    assert [r.split(" | ")[1:4] for r in rows] == [
        ["bitstar", "ours", "0"],
        ["bitstar", "ours", "1"],
        ["shortcut", "ours", "0"],
    ]
    assert "| 0.500 / 0.060 | -0.114 [-0.164, -0.064] p=<0.001 q=<0.001 |" in rows[2]
    assert "- data paths = `bitstar`: rigid/0 +, rigid/0 seed 1 0" in text
    assert "- data paths = `shortcut`: rigid/0 -" in text
    assert "- test band = `in_band`: + 1, - 1, 0 1 cells" in text
    (tmp_path / F.CONCLUSION).write_text("The data paths decide it.\n")
    assert F.section(tmp_path)[-2] == "The data paths decide it."


def test_render_includes_the_sibling_factor_study(tmp_path):
    paper = tmp_path / "results" / "paper"
    paper.mkdir(parents=True)
    assert "What decides" not in R.render(paper)
    _cell(tmp_path / "results" / "factors", "point/0", "raw", "ours", 0, 0.0, 1.0)
    doc = R.render(paper)
    assert "## What decides PNet_3 vs PNet_0" in doc and "`results/factors/`" in doc
    assert "What decides" not in R.render(paper, factors=tmp_path / "elsewhere")


def test_decomposition_splits_the_difference_into_gain_and_pruning(tmp_path):
    """PNet_3 - PNet_0 = (PNet_2 - PNet_0) + (PNet_3 - PNet_2), beside the data's density and
    the samples pruning kept (from summary.json); cells of other budgets are left out."""
    _cell(tmp_path, "point/0", "shortcut", "ours", 0, -0.06, 0.01)
    _cell(tmp_path, "point/0", "shortcut", "mpnet", 0, -0.02, 0.5)
    summary = {
        "datasets": {
            "D2": {"paths": 3000, "samples": 7120, "states_per_path": 3.3733},
            "D3": {"paths": 3000, "samples": 4120, "states_per_path": 3.3733},
        }
    }
    (tmp_path / "point_0" / "shortcut" / "ours" / "summary.json").write_text(json.dumps(summary))
    lines = F.decomposition(F.load_cells(tmp_path))
    rows = [ln for ln in lines if ln.startswith("| point/0")]
    # PNet_0 0.5; PNet_2 0.5 + 0.3; PNet_3 0.5 - 0.06
    assert rows == [
        "| point/0 | shortcut | 0 | 3.37 | 0.58 | 0.500 | 0.800 | 0.440 | +0.300 "
        "| -0.360 | -0.060 | 0.010 | 0.024 |"
    ]  # p, and q over the 12 p-values
    assert "\n".join(lines) in "\n".join(F.section(tmp_path))
    assert F.decomposition([]) == []
