"""Evaluation metrics, cached test queries / references, and the report artifacts.

No neural planning here (the end-to-end test in test_train_all.py runs
evaluate_env with a trained ensemble); these tests are fast and exact.
"""

import json
from pathlib import Path

import jax
import numpy as np
import pytest

from ntq_jax import Env, artifacts, make_env
from ntq_jax.experiment import config, references
from ntq_jax.experiment import evaluate as E
from ntq_jax.experiment import metrics as M
from ntq_jax.experiment import report as R
from ntq_jax.stats import wilson_interval
from ntq_jax.types import QUERY_KINDS, PlanCause


def test_metrics_by_hand():
    success = np.array([True, True, True, False, False])
    costs = np.array([2.0, 3.0, 5.0, np.inf, np.inf])
    cause = np.array(
        [
            PlanCause.SUCCESS,
            PlanCause.SUCCESS,
            PlanCause.SUCCESS,
            PlanCause.NO_PATH,
            PlanCause.INFEASIBLE,
        ],
        np.int8,
    )
    ref = np.array([1.0, 2.0, np.inf, 1.0, 1.0])
    status = np.array([0, 0, 2, 0, 0], np.int8)  # the reference timed out on query 2
    opt = np.array([1.0, 1.5, 4.0, 1.0, 1.0])
    m = M.metrics(success, costs, cause, ref, status, opt)
    assert m["successes"] == 3 and m["success_ratio"] == pytest.approx(0.6)
    assert m["success_ci95"] == pytest.approx(list(wilson_interval(3, 5)))
    assert m["cost_ratio"] == pytest.approx((2.0 + 1.5) / 2)  # only queries both solved
    assert m["cost_ratio_n"] == 2
    assert m["cost_ratio_opt"] == pytest.approx((2.0 + 2.0 + 1.25) / 3)
    assert m["failures"] == {"no_path": 1, "infeasible": 1, "invalid_query": 0}
    assert m["reference_failed"] == 1


def test_wilson_interval_contains_truth_at_nominal_rate():
    rng = np.random.default_rng(0)
    p, n = 0.9, 200
    hits = sum(
        lo <= p <= hi
        for lo, hi in (wilson_interval(int(k), n) for k in rng.binomial(n, p, size=2000))
    )
    assert 0.93 <= hits / 2000 <= 0.97


class FakeReference:
    """Straight-line 'planner': solves every query with cost |s - g|; counts its calls."""

    __name__ = "fake"

    def __init__(self):
        self.calls = 0

    def __call__(self, env, q, *, padding, seed):
        self.calls += 1
        k = len(q)

        class Res:
            paths = np.asarray(q, np.float32)
            lengths = np.full(k, 2, np.int32)
            costs = np.linalg.norm(q[:, 1] - q[:, 0], axis=1).astype(np.float64)
            status = np.zeros(k, np.int8)

        return Res()


@pytest.fixture(scope="module")
def cfg():
    return config.load(None, ["envs=[point/1]", "eval.k_test=40", "eval.gamma_queries=20000"])


def test_test_queries_are_fresh_cached_and_nontrivial(tmp_path, cfg):
    env = make_env("point/1")
    q = references.test_queries(env, cfg, "point_1", tmp_path)
    assert q["uniform"].shape == q["nontrivial"].shape == (40, 2, 2)
    assert np.all(np.asarray(env.is_valid(q["uniform"].reshape(-1, 2), padding=0.0)))
    free = np.asarray(env.steer_to(q["nontrivial"][:, 0], q["nontrivial"][:, 1], padding=0.0))
    assert not free.any()  # non-trivial on the evaluation geometry
    again = references.test_queries(env, cfg, "point_1", tmp_path)
    np.testing.assert_array_equal(q["nontrivial"], again["nontrivial"])
    other = references.test_queries(
        env, config.load(None, ["eval.k_test=40", "seed=1"]), "point_1", tmp_path / "b"
    )
    assert not np.allclose(other["uniform"], q["uniform"])
    # disjoint from the training stream: the data stage's uniform pool of the same seed
    train_q, _ = env.sample_queries(jax.random.key(cfg.seed), 40, 0.0)
    assert not np.any(np.all(np.isclose(train_q[:, None], q["uniform"][None]), axis=(2, 3)))


def test_reference_is_cached_and_has_the_optimum(tmp_path, cfg):
    env = make_env("point/1")
    q = references.test_queries(env, cfg, "point_1", tmp_path)
    fake = FakeReference()
    ref = references.reference_plans(env, cfg, "point/1", "point_1", q, tmp_path, fake)
    assert fake.calls == 2
    again = references.reference_plans(env, cfg, "point/1", "point_1", q, tmp_path, fake)
    assert fake.calls == 2 and str(again["planner"]) == "fake"
    changed = {k: v.copy() for k, v in q.items()}
    changed["nontrivial"][-1, 1, 0] += 1e-3  # only the last query's goal: a new reference
    references.reference_plans(env, cfg, "point/1", "point_1", changed, tmp_path, fake)
    assert fake.calls == 4
    # the visibility-graph optimum: never longer than the straight line on trivial queries,
    # strictly longer on the non-trivial ones
    assert np.all(ref["uniform_opt_costs"] >= ref["uniform_costs"] - 1e-4)
    assert np.all(ref["nontrivial_opt_costs"] > ref["nontrivial_costs"])


def _row(env, model, kind, steer, s, k=50, cost=1.05):
    return {
        "task": "point",
        "env": env,
        "env_slug": env.replace("/", "_"),
        "model": model,
        "member": int(model[-1]),
        "query_kind": kind,
        "steer": steer,
        "gamma_nt": 0.4,
        "gamma_nt_ci95": [0.39, 0.41],
        "reference_planner": "astar",
        "seconds_per_query": 1e-3,
        "compile_seconds": 2.0,
        "reference_seconds_per_query": 1e-2,
        "paths_file": "x",
        **M.metrics(
            np.arange(k) < s,
            np.full(k, cost),
            np.zeros(k, np.int8),
            np.ones(k),
            np.zeros(k, np.int8),
            np.ones(k),
        ),
    }


def test_report_layout(tmp_path):
    rows = [
        _row(e, f"PNet_{m}", kind, steer, 40 + m)
        for steer in (True, False)
        for e in ("point/0", "point/3")
        for m in range(4)
        for kind in QUERY_KINDS
    ]
    out = R.write_report(tmp_path, rows, envs=None, meta={"seed": 0})
    assert out and all(Path(f).is_file() for f in out.values())
    md = (tmp_path / "tables.md").read_text()
    assert "## Point robot planning" in md and "## Point robot planning without steerTo" in md
    assert "Environment point/3, gamma_nt = 0.400 [0.390, 0.410] (paper 0.628)" in md
    assert md.count("| PNet_3 | 0.860 [") == 4  # 43/50 in both kinds, both variants, 2 envs: 4 rows
    tex = (tmp_path / "tables.tex").read_text()
    assert tex.count("\\begin{tabular}") == 4 and "$\\mathsf{PNet}_0$ & 0.800 & 1.050" in tex
    assert "without $\\mathsf{steerTo}$" in tex
    csv_lines = (tmp_path / "results.csv").read_text().strip().splitlines()
    assert len(csv_lines) == 1 + len(rows)
    back = json.loads((tmp_path / "results.json").read_text())
    assert back["meta"] == {"seed": 0} and len(back["rows"]) == len(rows)
    assert (tmp_path / "figures" / "success_ratio.png").stat().st_size > 1000
    assert (tmp_path / "figures" / "success_ratio_nosteer.png").is_file()
    assert not list(tmp_path.rglob("*.tmp*"))


def test_report_shows_in_band_and_out_of_band_success(tmp_path):
    rows = [_row("point/0", f"PNet_{m}", kind, True, 40) for m in range(2) for kind in QUERY_KINDS]
    band = np.arange(50) < 30
    for r in rows:
        r["band_padding"] = 0.8
        r.update(M.band_metrics(np.arange(50) < 40, band))  # 30/30 in band, 10/20 out
    rows[-1] = {k: v for k, v in rows[-1].items() if "band" not in k}  # a row from before
    R.write_report(tmp_path, rows, figures=False)
    md = (tmp_path / "tables.md").read_text()
    assert "data padding (0.80)" in md
    lo, hi = wilson_interval(10, 20)
    detail = f"| 30 / 50 | 1.000 [{wilson_interval(30, 30)[0]:.3f}, 1.000] | 0.500 [{lo:.3f}, {hi:.3f}] |"
    assert md.count(detail) == 3
    assert md.count("| 0 | - | - | - |") == 1  # the old row: reference failed 0, no band fields
    assert md.count("| PNet_1 | 0.800 [") == 1  # the paper-layout table is unchanged
    lines = (tmp_path / "results.csv").read_text().strip().splitlines()
    head = lines[0].split(",")
    first = dict(zip(head, lines[1].split(",")))
    assert first["n_in_band"] == "30" and first["n_out_band"] == "20"
    assert float(first["success_out_band"]) == 0.5
    assert float(first["success_out_band_ci95_lo"]) == pytest.approx(lo)
    assert dict(zip(head, lines[-1].split(",")))["n_in_band"] == ""
    back = json.loads((tmp_path / "results.json").read_text())["rows"][0]
    assert back["successes_in_band"] == 30
    assert back["success_in_band_ci95"] == pytest.approx(list(wilson_interval(30, 30)))


def test_npz_roundtrip_rejects_other_fingerprints(tmp_path):
    f = tmp_path / "a.npz"
    artifacts.save_npz(f, fingerprint="abc", x=np.arange(3))
    assert artifacts.load_npz(f, "abc")["x"].tolist() == [0, 1, 2]
    assert artifacts.load_npz(f, "other") is None
    f.write_bytes(b"truncated")
    assert artifacts.load_npz(f) is None


def test_recheck_paths_checks_collisions_start_and_goal(tmp_path):
    env = Env.from_json(
        {
            "name": "box",
            "robot": {"kind": "point"},
            "bounds": [[0, 10], [0, 10]],
            "boxes": [[5.0, 5.0, 1.0, 1.0]],
            "padding": 0.0,
        }
    )
    q = np.array([[[1, 1], [9, 1]]] * 5, np.float32)
    paths = np.full((5, 3, 2), np.nan, np.float32)
    paths[0, :2] = [[1, 1], [9, 1]]  # good
    paths[1, :3] = [[1, 1], [5, 5], [9, 1]]  # through the box
    paths[2, :2] = [[1, 1], [8, 1]]  # does not end at the goal
    paths[3, :2] = [[1, 2], [9, 1]]  # does not start at the start
    paths[4, :3] = [[1, 1], [5, 5], [9, 1]]  # through the box, but not a success
    lengths = np.array([2, 3, 2, 2, 3], np.int32)
    success = np.array([True, True, True, True, False])
    f = E.paths_file(tmp_path, "box", 0, "uniform", True)
    artifacts.save_npz(f, queries=q, paths=paths, lengths=lengths, success=success)
    assert M.recheck_paths(env, f).tolist() == [True, False, False, False, True]
    # without steerTo a success stops within delta of the goal, which it does not reach
    g = E.paths_file(tmp_path, "box", 0, "uniform", False)
    paths[2, :2] = [[1, 1], [8.5, 1]]  # 0.5 from the goal
    artifacts.save_npz(g, queries=q, paths=paths, lengths=lengths, success=success)
    assert M.recheck_paths(env, g, delta=1.0).tolist() == [True, False, True, False, True]
    assert M.recheck_paths(env, g, delta=0.4).tolist() == [True, False, False, False, True]
    with pytest.raises(ValueError, match="delta"):
        M.recheck_paths(env, g)
    # a start already within delta: the one-state path passes if its state is valid
    one = np.full((2, 3, 2), np.nan, np.float32)
    one[:, 0] = [[1, 1], [4.5, 5]]  # free; inside the box
    q1 = np.array([[[1, 1], [1.5, 1]], [[4.5, 5], [4.5, 5.5]]], np.float32)
    h = E.paths_file(tmp_path, "box", 1, "uniform", False)
    artifacts.save_npz(
        h, queries=q1, paths=one, lengths=np.ones(2, np.int32), success=np.ones(2, bool)
    )
    assert M.recheck_paths(env, h, delta=1.0).tolist() == [True, False]
    assert M.recheck_paths(env, h, delta=0.4).tolist() == [False, False]


def test_recheck_without_steer_to_uses_the_robots_metric(tmp_path):
    """Rigid body: theta pi and -pi are one heading; the angle counts angle_weight (0.5)."""
    env = Env.from_json(
        {
            "name": "open",
            "robot": {"kind": "rigid_body"},
            "bounds": [[0, 10], [0, 10]],
            "boxes": [[9.5, 9.5, 0.1, 0.1]],
            "padding": 0.0,
        }
    )
    q = np.array(
        [[[2, 2, 0], [8, 2, -np.pi]], [[2, 5, 0], [8, 5, 0.0]], [[2, 8, 0], [8, 8, 0.0]]],
        np.float32,
    )
    paths = np.full((3, 2, 3), np.nan, np.float32)
    paths[0] = [[2, 2, 0], [8, 2, np.pi]]  # 0 from the goal, 2 pi in raw coordinates
    paths[1] = [[2, 5, 0], [7.6, 5, 0.7]]  # 0.4 + 0.35 = 0.75 (Euclidean 0.81)
    paths[2] = [[2, 8, 0], [7.5, 8, 0.0]]  # 0.5: Euclidean and metric agree
    f = E.paths_file(tmp_path, "open", 0, "uniform", False)
    artifacts.save_npz(
        f, queries=q, paths=paths, lengths=np.full(3, 2, np.int32), success=np.ones(3, bool)
    )
    assert M.recheck_paths(env, f, delta=0.78).tolist() == [True, True, True]
    assert M.recheck_paths(env, f, delta=0.6).tolist() == [True, False, True]
    assert M.recheck_paths(env, f, delta=0.1).tolist() == [True, False, False]


def test_band_metrics_by_hand():
    success = np.array([True, True, False, True, False, True])
    band = np.array([True, False, False, True, True, True])
    m = M.band_metrics(success, band)
    assert (m["n_in_band"], m["n_out_band"]) == (4, 2)
    assert (m["successes_in_band"], m["successes_out_band"]) == (3, 1)
    assert m["success_in_band"] == pytest.approx(0.75) and m["success_out_band"] == 0.5
    assert m["success_in_band_ci95"] == pytest.approx(list(wilson_interval(3, 4)))
    assert m["success_out_band_ci95"] == pytest.approx(list(wilson_interval(1, 2)))
    empty = M.band_metrics(success, np.ones(6, bool))
    assert empty["n_out_band"] == 0 and np.isnan(empty["success_out_band"])
    assert empty["success_in_band"] == pytest.approx(4 / 6)


def test_in_band_partitions_the_test_queries(tmp_path, cfg):
    """point/1's test queries are sampled at padding 0; in band = both endpoints valid at 0.8."""
    env = make_env("point/1")
    assert env.padding > 0
    q = references.test_queries(env, cfg, "point_1", tmp_path)
    for kind in QUERY_KINDS:
        band = M.in_band(env, q[kind])
        assert band.shape == (len(q[kind]),) and band.dtype == bool
        ok = np.asarray(env.is_valid(q[kind].reshape(-1, 2))).reshape(-1, 2)  # env padding
        np.testing.assert_array_equal(band, ok.all(axis=1))
        success = np.arange(len(band)) % 3 != 0
        m = M.band_metrics(success, band)
        assert m["n_in_band"] + m["n_out_band"] == len(band)
        assert m["successes_in_band"] + m["successes_out_band"] == success.sum()
    # the non-trivial queries hug the obstacles: some have an endpoint in the band
    assert not M.in_band(env, q["nontrivial"]).all()
    assert M.in_band(env, q["uniform"]).any()


def test_timings_are_kept_apart(tmp_path):
    """Issue 52 (rough edge 13): two runs that differ only in wall-clock times write the same
    bytes of results.csv, tables.md and tables.tex; the times are in timings.csv."""
    rows = [_row("point/0", f"PNet_{m}", kind, True, 40) for m in range(2) for kind in QUERY_KINDS]
    slow = [
        {
            **r,
            "seconds_per_query": 7.5,
            "compile_seconds": 30.25,
            "reference_seconds_per_query": 0.125,
        }
        for r in rows
    ]
    a, b = tmp_path / "a", tmp_path / "b"
    for run, rs in ((a, rows), (b, slow)):
        run.mkdir()
        out = R.write_report(run, rs, figures=False)
        assert out["timings.csv"] == run / "timings.csv"
    for name in ("results.csv", "tables.md", "tables.tex"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    assert "ms / query" not in (a / "tables.md").read_text()
    assert not set(R.TIMING_FIELDS) & set(
        (a / "results.csv").read_text().splitlines()[0].split(",")
    )
    lines = (b / "timings.csv").read_text().strip().splitlines()
    assert lines[0].split(",") == R.TIMING_CSV_FIELDS and len(lines) == 1 + len(rows)
    assert lines[1] == "point,point/0,PNet_0,uniform,True,7.5,30.25,0.125"
    assert (a / "timings.csv").read_bytes() != (b / "timings.csv").read_bytes()
