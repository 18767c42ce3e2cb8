"""Paired comparisons (ntq_jax.stats) and their report (ntq_jax.experiment.paired.comparisons):
McNemar's exact test against scipy and a hand-computed case, the coverage of Newcombe's
paired interval and of the paired bootstrap in seeded simulations, the bootstrap's
determinism per seed, the Wilcoxon edge cases, and the comparison table of a small
synthetic run folder (including an ensemble row compared with its best member).
"""

import csv
import io
import json
import warnings

import numpy as np
import pytest
from scipy.stats import binomtest, wilcoxon

from ntq_jax import stats as S
from ntq_jax.artifacts import save_npz
from ntq_jax.experiment import paired as P
from ntq_jax.experiment import report as R

# ---------------------------------------------------------------------------
# McNemar
# ---------------------------------------------------------------------------


def test_mcnemar_exact_known_tables():
    assert S.mcnemar_exact(5, 0) == pytest.approx(2 * 0.5**5)  # = 0.0625
    assert S.mcnemar_exact(0, 5) == pytest.approx(0.0625)
    assert S.mcnemar_exact(10, 2) == pytest.approx(binomtest(10, 12, 0.5).pvalue)
    # by hand: P(X <= 2 | 12, 1/2) = (1 + 12 + 66) / 4096, doubled
    assert S.mcnemar_exact(10, 2) == pytest.approx(2 * 79 / 4096)
    assert S.mcnemar_exact(3, 3) == 1.0 and S.mcnemar_exact(0, 0) == 1.0
    with pytest.raises(ValueError):
        S.mcnemar_exact(-1, 2)


def test_paired_comparison_counts_the_discordant_pairs():
    sa = np.array([1, 1, 1, 1, 0, 0, 1, 0], bool)
    sb = np.array([1, 0, 0, 0, 0, 1, 1, 0], bool)
    got = S.paired_success_difference(sa, sb)
    assert (got["both"], got["only_a"], got["only_b"], got["neither"], got["n"]) == (2, 3, 1, 2, 8)
    assert got["diff"] == pytest.approx(2 / 8)
    lo, hi = got["ci"]
    assert -1 <= lo < got["diff"] < hi <= 1
    # swapping the models mirrors the interval
    back = S.paired_success_difference(sb, sa)
    assert back["diff"] == pytest.approx(-got["diff"])
    assert back["ci"] == pytest.approx([-hi, -lo])
    # identical models: difference 0, an interval around it
    same = S.paired_success_difference(sa, sa)
    assert same["diff"] == 0 and same["ci"][0] < 0 < same["ci"][1]
    assert np.isnan(S.paired_success_difference([], [])["diff"])


def _table(a, b, c, d):
    """Paired outcomes with ``a`` both, ``b`` only A, ``c`` only B, ``d`` neither."""
    sa = np.array([1] * a + [1] * b + [0] * c + [0] * d, bool)
    sb = np.array([1] * a + [0] * b + [1] * c + [0] * d, bool)
    return sa, sb


def test_newcombe_interval_matches_a_published_example():
    """Cavo et al. (2012) in Fagerland, Lydersen & Laake, Statistical Analysis of Contingency
    Tables (2017), ch. 8: Newcombe square-and-add, -0.0621 (95% CI -0.1186 to -0.0046)."""
    got = S.paired_success_difference(*_table(59, 6, 16, 80))
    assert got["diff"] == pytest.approx(-0.0621, abs=5e-5)
    assert got["ci"] == pytest.approx([-0.1186, -0.0046], abs=5e-5)


def test_newcombe_interval_covers_the_true_difference():
    """>= 90% coverage (nominal 95%) over 200 seeded simulations of correlated pairs."""
    rng = np.random.default_rng(123)
    n, p_a, p_b = 150, 0.75, 0.65
    covered = 0
    for _ in range(200):
        u = rng.random(n)  # a shared query difficulty: strongly correlated outcomes
        v = rng.random(n)
        z = np.where(rng.random(n) < 0.7, u, v)
        sa, sb = u < p_a, z < p_b
        # exact marginals: P(sa) = p_a, P(sb) = p_b, so the true difference is p_a - p_b
        lo, hi = S.paired_success_difference(sa, sb)["ci"]
        covered += lo <= p_a - p_b <= hi
    assert covered >= 180


# ---------------------------------------------------------------------------
# Cost: paired bootstrap and Wilcoxon
# ---------------------------------------------------------------------------


def test_bootstrap_is_deterministic_per_seed_and_covers():
    rng = np.random.default_rng(7)
    x = 1 + rng.random(60)
    y = x + rng.normal(0.02, 0.05, 60)
    a = S.paired_cost_difference(x, y, seed=3)
    assert a == S.paired_cost_difference(x, y, seed=3)
    assert a["ci"] != S.paired_cost_difference(x, y, seed=4)["ci"]
    assert a["n"] == 60 and a["diff"] == pytest.approx(np.mean(x - y))
    assert a["ci"][0] < a["diff"] < a["ci"][1]
    # coverage of the true mean difference (-0.02): >= 90% over 200 simulations
    covered = 0
    for _ in range(200):
        x = 1 + rng.random(40)
        y = x + rng.normal(0.02, 0.05, 40)
        lo, hi = S.paired_cost_difference(x, y, n_boot=1000, seed=0)["ci"]
        covered += lo <= -0.02 <= hi
    assert covered >= 180


def test_bootstrap_chunks_do_not_change_the_draws(monkeypatch):
    """Chunking depends on n only: a tiny chunk size gives a valid, deterministic result."""
    x, y = np.arange(30.0), np.arange(30.0)[::-1]
    monkeypatch.setattr(S, "_MAX_DRAWS", 100)
    a = S.paired_cost_difference(x, y, n_boot=500)
    assert a == S.paired_cost_difference(x, y, n_boot=500)
    assert a["ci"][0] <= 0 <= a["ci"][1]


def test_cost_and_wilcoxon_edge_cases():
    nan_ci = S.paired_cost_difference([], [])
    assert nan_ci["n"] == 0 and np.isnan(nan_ci["diff"]) and np.all(np.isnan(nan_ci["ci"]))
    one = S.paired_cost_difference([1.2], [1.0])
    assert one["diff"] == pytest.approx(0.2) and np.all(np.isnan(one["ci"]))
    assert np.isnan(S.wilcoxon_p([], []))
    assert np.isnan(S.wilcoxon_p([1.0], [2.0]))  # n < 2
    assert np.isnan(S.wilcoxon_p([1.0, 2.0, 3.0], [1.0, 2.0, 3.0]))  # all differences zero
    x = np.array([1.0, 1.3, 1.1, 1.7, 1.2, 1.05, 1.4])
    y = np.array([1.1, 1.2, 1.0, 1.5, 1.0, 1.0, 1.1])
    assert S.wilcoxon_p(x, y) == pytest.approx(wilcoxon(x - y).pvalue)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert 0 <= S.wilcoxon_p([1.0, 2.0, 1.0], [1.0, 1.0, 2.0]) <= 1  # ties, one zero


def test_wilcoxon_with_zeros_or_ties_is_scipys_exact_sign_flip_test():
    """Up to 13 pairs with zeros or ties scipy runs a permutation test over all sign flips
    (about a second a call); wilcoxon_p computes the same p-value itself, to the bit."""
    # by hand: d = (1, -1, 2, 0) -> ranks (1.5, 1.5, 3), R+ = 4.5; the 8 flips' R+ are
    # 0, 1.5, 1.5, 3, 3, 4.5, 4.5, 6: P(<= 4.5) = 7/8, P(>= 4.5) = 3/8, p = 2 * 3/8
    assert S.wilcoxon_p([1.0, 0.0, 2.0, 5.0], [0.0, 1.0, 0.0, 5.0]) == 0.75
    rng = np.random.default_rng(4)
    for n in (2, 5, 9, 13):
        x = rng.integers(0, 4, n) * rng.choice([1.0, 0.5], n)
        y = rng.integers(0, 4, n).astype(float)
        x[0], y[0] = 3.0, 1.0  # at least one non-zero difference
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ref = wilcoxon(x - y).pvalue
        assert S.wilcoxon_p(x, y) == ref, (n, x - y)


def test_paired_comparison_uses_queries_both_solve_with_a_reference():
    k = 8
    inf = np.inf
    a = {
        "success": np.array([1, 1, 1, 1, 1, 0, 0, 1], bool),
        "costs": np.array([2.0, 3.0, 4.0, 5.0, 6.0, inf, inf, 9.0]),
        "ref_costs": np.array([1.0, 1.0, 2.0, 2.0, inf, 1.0, 1.0, 3.0]),
        "ref_status": np.array([0, 0, 0, 0, 2, 0, 0, 0], np.int8),
        "queries": np.zeros((k, 2, 2), np.float32),
    }
    b = dict(
        a,
        success=np.array([1, 1, 0, 1, 1, 1, 0, 1], bool),
        costs=np.array([1.5, 3.0, inf, 4.0, 5.0, 2.0, inf, 6.0]),
    )
    got = S.paired_comparison(a, b, n_boot=200)
    # both solve: 0, 1, 3, 4, 7; query 4 has no reference cost
    assert got["cost_n"] == 4
    assert got["cost_ratio_diff"] == pytest.approx(np.mean([0.5, 0.0, 0.5, 1.0]))
    assert (got["only_a"], got["only_b"]) == (1, 1) and got["mcnemar_p"] == 1.0
    assert got["success_diff"] == 0.0
    with pytest.raises(ValueError, match="different queries"):
        S.paired_comparison(a, dict(b, queries=np.ones((k, 2, 2), np.float32)))


# ---------------------------------------------------------------------------
# Report: a synthetic run folder
# ---------------------------------------------------------------------------

K = 40


def _synthetic_run(tmp_path):
    """Rows and paths files of point/0, steerTo on: PNet_0..3 and an ensemble row."""
    rng = np.random.default_rng(0)
    queries = rng.random((K, 2, 2)).astype(np.float32)
    ref = 1 + rng.random(K)
    hard = rng.random(K)
    rows = []
    # PNet_0 solves 50%, PNet_1 60%, PNet_2 70%, PNet_3 95%, the ensemble 100%
    for model, p in (
        ("PNet_0", 0.5),
        ("PNet_1", 0.6),
        ("PNet_2", 0.7),
        ("PNet_3", 0.95),
        ("PNet_ens", 1.01),
    ):
        for kind in ("uniform", "nontrivial"):
            success = hard < p
            cost = np.where(success, ref * (1.2 if model == "PNet_0" else 1.1), np.inf)
            f = f"paths/point_0/{model}_{kind}.npz"
            save_npz(
                tmp_path / f,
                queries=queries,
                success=success,
                costs=cost,
                ref_costs=ref,
                ref_status=np.zeros(K, np.int8),
            )
            lo_hi = S.wilson_interval(int(success.sum()), K)
            rows.append(
                {
                    "task": "point",
                    "env": "point/0",
                    "model": model,
                    "query_kind": kind,
                    "steer": True,
                    "k_test": K,
                    "successes": int(success.sum()),
                    "success_ratio": success.mean(),
                    "success_ci95": list(lo_hi),
                    "cost_ratio": 1.1,
                    "seconds_per_query": 1e-3,
                    "compile_seconds": 1.0,
                    "failures": {},
                    "reference_failed": 0,
                    "reference_planner": "astar",
                    "gamma_nt": 0.4,
                    "paths_file": f,
                }
            )
    return rows


def test_report_shows_the_paired_comparisons(tmp_path):
    rows = _synthetic_run(tmp_path)
    assert ("PNet_ens", P.BEST_MEMBER) in P.DEFAULT_PAIRS  # the ensemble vs its best member
    R.write_report(tmp_path, [r for r in rows], figures=False)
    md = (tmp_path / "tables.md").read_text()
    assert "Detail, paired comparisons" in md
    for m in (1, 2, 3):
        for kind in ("uniform", "nontrivial"):
            assert f"| PNet_{m} | PNet_0 | {kind} |" in md
    # the ensemble against its best single member (PNet_3)
    assert md.count("| PNet_ens | PNet_3 (best member) | ") == 2
    comps = json.loads((tmp_path / "results.json").read_text())["comparisons"]
    assert len(comps) == 8
    c = next(c for c in comps if c["model"] == "PNet_3" and c["query_kind"] == "nontrivial")
    assert c["baseline"] == "PNet_0" and c["only_b"] == 0 and c["n"] == K
    assert c["mcnemar_p"] == pytest.approx(S.mcnemar_exact(c["only_a"], 0))
    assert c["success_diff"] == pytest.approx(c["only_a"] / K)
    assert c["cost_ratio_diff"] == pytest.approx(1.1 - 1.2)
    assert c["wilcoxon_p"] < 0.05 and c["cost_n"] == c["both"]
    ens = [c for c in comps if c["model"] == "PNet_ens"]
    assert {c["baseline_rule"] for c in ens} == {P.BEST_MEMBER}
    assert all(c["cost_ratio_diff"] == pytest.approx(0.0) and c["wilcoxon_p"] is None for c in ens)
    # results.csv: each row's first comparison in the vs_* columns
    lines = list(csv.DictReader(io.StringIO((tmp_path / "results.csv").read_text())))
    assert len(lines) == len(rows)
    by = {(ln["model"], ln["query_kind"]): ln for ln in lines}
    assert by[("PNet_0", "uniform")]["vs_model"] == ""
    assert by[("PNet_3", "nontrivial")]["vs_model"] == "PNet_0"
    assert float(by[("PNet_3", "nontrivial")]["vs_mcnemar_p"]) == pytest.approx(c["mcnemar_p"])
    assert by[("PNet_ens", "uniform")]["vs_model"] == "PNet_3"


def test_comparisons_leave_out_what_they_cannot_pair(tmp_path):
    rows = _synthetic_run(tmp_path)
    (tmp_path / rows[0]["paths_file"]).unlink()  # PNet_0 uniform
    with pytest.warns(UserWarning, match="1 paths file"):
        comps = P.comparisons(tmp_path, rows, n_boot=100)
    assert {(c["model"], c["query_kind"]) for c in comps} == {
        (f"PNet_{m}", "nontrivial") for m in (1, 2, 3)
    } | {  # the ensemble vs PNet_3: both kinds
        ("PNet_ens", k) for k in ("uniform", "nontrivial")
    }
    # a baseline absent from the rows, and a model against itself: nothing
    assert P.comparisons(tmp_path, rows, [("PNet_1", "PNet_9"), ("PNet_1", "PNet_1")]) == []
    assert P.best_member({r["model"]: r for r in rows if r["query_kind"] == "uniform"}) == "PNet_3"
    tie = {m: {"successes": 5} for m in ("PNet_2", "PNet_1", "PNet_ens")}
    assert P.best_member(tie) == "PNet_1" and P.best_member({"PNet_ens": {"successes": 1}}) is None
