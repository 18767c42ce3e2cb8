"""planner.data_paths: raw / shortcut / resampled data paths, and what pruning then removes."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import LineString, box

from ntq_jax import Env, make_env
from ntq_jax.data.include import include_data
from ntq_jax.experiment import config
from ntq_jax.experiment.config import ConfigError
from ntq_jax.planners import plan
from ntq_jax.planners.jobs import planner_options
from ntq_jax.planners.path_modes import shape_paths
from ntq_jax.planners.resample import resample_paths
from ntq_jax.planners.verify import finalize
from ntq_jax.robots.batch import distances

WALLS = {
    "name": "walls",
    "robot": {"kind": "point"},
    "bounds": [[0, 10], [0, 10]],
    "boxes": [[3, 3.5, 0.5, 3.5], [7, 6.5, 0.5, 3.5]],
    "discs": [],
    "padding": 0.2,
}


def _costs(robot, p, n):
    return np.array(
        [
            distances(robot, p[b, : max(n[b] - 1, 0)], p[b, 1 : n[b]]).astype(np.float64).sum()
            for b in range(len(n))
        ]
    )


def test_resampled_segments_never_exceed_the_spacing_and_keep_vertices_and_cost():
    for name in ("point/0", "rigid/0", "nlink/4"):
        env = make_env(name)
        rng = np.random.default_rng(1)
        lo, hi = (np.asarray(a) for a in env.robot.config_bounds(env.world))
        n = np.array([5, 2, 1, 0, 7])
        p = np.full((5, 7, env.dim), np.nan, np.float32)
        for b, m in enumerate(n):
            p[b, :m] = rng.uniform(lo, hi, (m, env.dim))
        for spacing in (0.05, 0.7, 100.0):
            out, m = resample_paths(env.robot, p, n, spacing)
            assert m[2] == 1 and m[3] == 0 and np.isnan(out[3]).all()
            np.testing.assert_array_equal(out[2, 0], p[2, 0])
            for b in (0, 1, 4):
                q = out[b, : m[b]]
                d = distances(env.robot, q[:-1], q[1:])
                assert d.max() <= spacing * (1 + 1e-5) + 1e-6, (name, spacing, d.max())
                assert np.isnan(out[b, m[b] :]).all()
                # every input vertex is kept exactly, in order
                idx = [int(np.flatnonzero((q == v).all(1))[0]) for v in p[b, : n[b]]]
                assert idx == sorted(idx) and idx[0] == 0 and idx[-1] == m[b] - 1
            if spacing == 100.0:
                np.testing.assert_array_equal(m, n)  # nothing to insert
            np.testing.assert_allclose(
                _costs(env.robot, out, m)[[0, 1, 4]], _costs(env.robot, p, n)[[0, 1, 4]], rtol=1e-5
            )


def test_resample_rejects_bad_spacing():
    env = make_env("point/0")
    p = np.zeros((1, 2, 2), np.float32)
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="spacing"):
            resample_paths(env.robot, p, np.array([2]), bad)


def _plan_modes(env, q, planner, **kw):
    raw = plan(env, q, planner, padding=env.padding, smooth=False, **kw)
    cut = plan(env, q, planner, padding=env.padding, **kw)
    return raw, cut


def test_modes_on_a_tiny_map():
    """raw keeps the planner's vertices, shortcut is the planner's default, a number resamples
    the shortcut path (same cost, segments <= spacing) and bitstar-like planners are
    shortcut here."""
    env = Env.from_json(WALLS)
    q = np.array([[[1, 1], [9, 9]], [[1, 9], [9, 1]], [[5, 1], [5, 9]]], np.float32)
    raw, cut = _plan_modes(env, q, "astar", resolution=0.25)
    assert raw.solved.all() and cut.solved.all()
    same, _ = shape_paths(env, raw, "raw", "astar", env.padding)
    assert same is raw  # the planner's own vertices, untouched
    assert (raw.lengths > 3 * cut.lengths).all()
    res, info = shape_paths(env, cut, 0.5, "astar", env.padding)
    assert info == {"mode": 0.5, "shortcut_kept": 0, "resample_kept": 0}
    np.testing.assert_allclose(res.costs, cut.costs, rtol=1e-5)
    for b in range(3):
        pr, pc = res.path(b), cut.path(b)
        if len(pc) == 2:  # a direct connection (query 2 here) stays its two ends
            np.testing.assert_array_equal(pr, pc)
            continue
        assert (distances(env.robot, pr[:-1], pr[1:]) <= 0.5 * (1 + 1e-5)).all()
        assert all((pr == v).all(1).any() for v in pc)  # the corners are kept
    assert cut.lengths[2] == 2 and (cut.lengths[:2] > 2).all()
    # a planner without its own smoothing (here: the raw grid path as a "custom" planner)
    # is shortcut by shape_paths: the result equals the planner's own shortcut's cost
    sc, info = shape_paths(env, raw, "shortcut", "custom", env.padding)
    assert info["shortcut_kept"] == 0
    assert (sc.lengths <= raw.lengths).all() and (sc.costs <= raw.costs + 1e-4).all()
    assert (sc.lengths < raw.lengths / 3).all()


def _clearance(path):
    """Shapely: ``(n-1, boxes)`` distance of each ``(pi_i, pi_end)`` to each box."""
    polys = [box(cx - hx, cy - hy, cx + hx, cy + hy) for cx, cy, hx, hy in WALLS["boxes"]]
    end = path[-1]
    return np.array(
        [
            [
                LineString([p, end]).distance(b)
                if not np.array_equal(p, end)
                else b.distance(LineString([p, p + 1e-9]))
                for b in polys
            ]
            for p in path[:-1]
        ]
    )


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 10_000))
def test_pruning_on_a_resampled_path_removes_exactly_the_trivial_samples(seed):
    """On multi-vertex paths, pruning drops exactly the samples whose (pi_i, pi_end) is free
    (shapely oracle), keeps the rest in order, and the unpruned set has one sample per segment."""
    env = Env.from_json(WALLS)
    rng = np.random.default_rng(seed)
    q = rng.uniform(0.5, 9.5, (8, 2, 2)).astype(np.float32)
    res = plan(env, q, "astar", padding=env.padding, resolution=0.25)
    res, _ = shape_paths(env, res, 0.6, "astar", env.padding)
    rows = np.flatnonzero(res.solved)
    paths, lens = res.paths[rows], res.lengths[rows]
    full = include_data(env, paths, lens, prune=False, padding=env.padding)
    pruned = include_data(env, paths, lens, prune=True, padding=env.padding)
    for j in range(len(rows)):
        path = paths[j, : lens[j]]
        assert (full[2] == j).sum() == lens[j] - 1
        clear = _clearance(path) - env.padding
        if (np.abs(clear) < 1e-4).any():
            continue  # a connection grazing the padding: float32 and shapely may disagree
        trivial = (clear > 0).all(axis=1)
        np.testing.assert_array_equal(pruned[0][pruned[2] == j][:, :2], path[:-1][~trivial])
        np.testing.assert_array_equal(pruned[1][pruned[2] == j], path[1:][~trivial])


def test_config_key_reaches_the_data_planner_and_the_fingerprint():
    from ntq_jax.data.generate import resolve_run

    base = config.load(None, [])
    assert "data_paths" not in base.to_dict()["planner"]
    base_rigid = config.planner_settings(base, "rigid/0")
    assert planner_options(base_rigid, "roadmap").get("smooth") is None
    for mode, smooth in (("raw", False), ("shortcut", True), (0.4, True)):
        cfg = config.load(None, [f"planner.data_paths={mode}"])
        assert cfg.planner.data_paths_for("rigid/0") == mode
        rigid = config.planner_settings(cfg, "rigid/0")
        assert planner_options(rigid, "roadmap")["smooth"] is smooth
        assert "smooth" not in planner_options(rigid, "bitstar")
        assert "smooth" not in planner_options(rigid, "roadmap", evaluation=True)
        assert cfg.hash() != base.hash()
    env = make_env("point/0")
    opts = [
        config.data_options(config.load(None, [f"planner.data_paths={m}"]), "point/0")
        for m in ("raw", "shortcut", 0.4, 0.5)
    ]
    fps = {resolve_run(env, o, "/tmp/x", "point/0", None).fingerprint for o in opts}
    assert len(fps) == 4
    # per environment, and the earlier spelling smooth_data
    cfg = config.load(None, ["planner.per_env=[{env: rigid/0, data_paths: 0.3}]"])
    assert cfg.planner.data_paths_for("rigid/0") == 0.3
    assert cfg.planner.data_paths_for("point/0") is None
    old = config.load(None, ["planner.smooth_data=false"])
    assert old.planner.data_paths_for("point/0") == "raw"
    assert "data_paths" not in old.to_dict()["planner"]
    for bad, msg in (("fast", "raw, shortcut"), ("0", "> 0"), ("-1", "> 0"), ("true", "")):
        with pytest.raises(ConfigError, match=r"planner\.data_paths"):
            config.load(None, [f"planner.data_paths={bad}"])
    with pytest.raises(ConfigError, match=r"planner\.smooth_data"):
        config.load(None, ["planner.smooth_data=false", "planner.data_paths=raw"])


def test_data_check_reaches_the_planner_the_verification_and_the_fingerprint():
    """planner.data_check: absent from the hash when unset, passed to the data planner (not
    to the evaluation, which has eval.motion_check), to a user's planner's verification, and
    into the datasets' fingerprint; a bad value is one config error."""
    from ntq_jax.data.generate import resolve_run

    base = config.load(None, [])
    assert "data_check" not in base.to_dict()["planner"]
    assert "check" not in planner_options(config.planner_settings(base, "rigid/0"), "roadmap")
    cfg = config.load(None, ["planner.data_check=certified", "eval.motion_check=discretized"])
    assert cfg.hash() != base.hash()
    ps = config.planner_settings(cfg, "rigid/0")
    assert planner_options(ps, "roadmap")["check"] == "certified"
    assert planner_options(ps, "roadmap", evaluation=True)["check"] == "discretized"
    env = make_env("point/0")
    runs = [
        resolve_run(env, config.data_options(c, "point/0"), "/tmp/x", "point/0", None)
        for c in (base, cfg)
    ]
    assert runs[0].data_check == "discretized" and runs[1].data_check == "certified"
    assert runs[0].fingerprint != runs[1].fingerprint
    with pytest.raises(ConfigError, match=r"planner\.data_check"):
        config.load(None, ["planner.data_check=exact"])


def test_a_user_planner_is_verified_with_the_data_check(monkeypatch):
    """plan_chunk's ``verify`` names the check its verification (``finalize``) uses:
    ``True`` the discretised one, ``"certified"`` the certified one, ``False`` none."""
    from ntq_jax.planners import jobs
    from ntq_jax.types import PlanResult, PlanStatus

    env = Env.from_json(WALLS)
    q = np.array([[[1, 1], [1, 9]]], np.float32)
    seen = []

    def spy(*args, **kw):
        seen.append(args[7] if len(args) > 7 else kw.get("check", "discretized"))
        return finalize(*args, **kw)

    def planner(env, queries, *, padding, seed):
        status = np.full(1, PlanStatus.SOLVED, np.int8)
        return PlanResult(queries.copy(), np.array([2], np.int32), np.zeros(1), status, {})

    monkeypatch.setattr(jobs, "finalize", spy)
    for verify in (True, "certified", False):
        res, rejected = jobs.plan_chunk(None, env, q, planner, verify, env.padding, 0)
        assert res.solved.all() and not rejected.any()
    assert seen == ["discretized", "certified"]


def test_a_spacing_too_fine_for_the_map_is_refused_before_any_work(tmp_path, capsys):
    """planner.data_paths=1.0e-9 failed only after planning (a 10.1 TiB allocation naming no
    key) and 1.0e-4 made 133,000 waypoints per path: refused up front, naming the key, the
    map and the smallest spacing allowed (data.limits.MAX_CROSSING_WAYPOINTS per crossing)."""
    from script_loader import load_script

    from ntq_jax import data

    cfg = config.load(None, ["planner.data_paths=1.0e-9"])
    with pytest.raises(ConfigError, match=r"planner\.data_paths 1e-09 for point/0: .* spacing >= "):
        data.generate_datasets(
            make_env("point/0"),
            config.data_options(cfg, "point/0"),
            tmp_path / "d",
            env_name="point/0",
            progress=False,
            figure=False,
        )
    assert not (tmp_path / "d").exists()
    argv = [
        "--set",
        "envs=[point/0]",
        "--set",
        "planner.data_paths=1.0e-4",
        "--out",
        str(tmp_path / "run"),
        "--no-progress",
    ]
    assert load_script("train_all").main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "planner.data_paths 0.0001 for point/0" in err[0], err
    assert not (tmp_path / "run").exists()


def test_a_roadmap_beyond_memory_is_refused_before_any_work(tmp_path):
    """milestones: 1e12 ran 455 s, then blamed "free space is too small"."""
    from ntq_jax import data

    cfg = config.load(None, ["planner.name=roadmap", "planner.milestones=1e12"])
    with pytest.raises(
        ConfigError,
        match=r"planner\.milestones 1,000,000,000,000 for rigid/0: "
        r".* GB\) would not fit .* use at most ",
    ):
        data.generate_datasets(
            make_env("rigid/0"),
            config.data_options(cfg, "rigid/0"),
            tmp_path / "d",
            env_name="rigid/0",
            progress=False,
            figure=False,
        )
    assert not (tmp_path / "d").exists()
    from ntq_jax.data.limits import check_roadmap

    check_roadmap(make_env("rigid/0"), {"milestones": 20_000, "k": None, "grow_rounds": 2}, "x")


def _record_script():
    from script_loader import load_script

    return load_script("record_paths")


def test_datasets_rebuild_from_a_record_without_planning(tmp_path, monkeypatch):
    """A record (scripts/record_paths.py) serves data generation: the same datasets as
    planning the pools, with no chunk planned; a record of other queries is refused."""
    from ntq_jax import data
    from ntq_jax.planners import jobs as planning

    sets = ["data.k_train=12", "data.gamma_queries=500", "data.gamma_eval=false"]
    rec = tmp_path / "rec"
    argv = [
        "--config",
        "configs/point_small.yaml",
        "--env",
        "point/2",
        "--planner",
        "astar",
        "--chunk",
        "5",
        "--out",
        str(rec),
        "--no-progress",
    ]
    assert _record_script().main(argv + [a for s in sets for a in ("--set", s)]) == 0
    assert sorted(p.name for p in (rec / "N").iterdir())[0] == "plan_000000000_000000005.npz"
    env = make_env("point/2")
    plain = config.load("configs/point_small.yaml", sets)
    data.generate_datasets(
        env,
        config.data_options(plain, "point/2"),
        tmp_path / "planned",
        env_name="point/2",
        progress=False,
        figure=False,
    )
    written = []
    monkeypatch.setattr(planning, "chunk_written", written.append)
    cfg = config.load(
        "configs/point_small.yaml", sets + [f"data.per_env=[{{env: point/2, paths_from: '{rec}'}}]"]
    )
    out = data.generate_datasets(
        env,
        config.data_options(cfg, "point/2"),
        tmp_path / "replayed",
        env_name="point/2",
        progress=False,
        figure=False,
    )
    assert written == [] and out["reused_queries"] == out["planned_queries"] == 24
    for ds in ("D0", "D1", "D2", "D3"):
        for arr in ("inputs", "targets", "paths", "queries"):
            np.testing.assert_array_equal(
                np.load(tmp_path / "planned" / "point_2" / ds / f"{arr}.npy"),
                np.load(tmp_path / "replayed" / "point_2" / ds / f"{arr}.npy"),
            )
    other = config.load(
        "configs/point_small.yaml",
        sets + ["seed=1", f"data.per_env=[{{env: point/2, paths_from: '{rec}'}}]"],
    )
    with pytest.raises(ValueError, match="with seed 0, not point/2 at 0.8 with seed 1"):
        data.generate_datasets(
            env,
            config.data_options(other, "point/2"),
            tmp_path / "other",
            env_name="point/2",
            progress=False,
            figure=False,
        )
    with pytest.raises(ValueError, match="records point/2"):
        p1 = config.load(
            "configs/point_small.yaml",
            sets + [f"data.per_env=[{{env: point/1, paths_from: '{rec}'}}]"],
        )
        data.generate_datasets(
            make_env("point/1"),
            config.data_options(p1, "point/1"),
            tmp_path / "p1",
            env_name="point/1",
            progress=False,
            figure=False,
        )


def test_the_committed_bitstar_record_reverifies():
    """An independent check of the committed BIT* chunks of rigid/0 (results/data_paths/bitstar):
    every solved path starts at its query's start and ends at its goal, is NaN after its
    length, has every segment free by the environment's steerTo at the data padding, and
    costs the sum of its segments in the robot's metric; the status is a PlanStatus."""
    import json
    import re
    from pathlib import Path

    from ntq_jax import PlanStatus

    rec = Path(__file__).resolve().parent.parent / "results" / "data_paths" / "bitstar" / "rigid_0"
    meta = json.loads((rec / "record.json").read_text())
    env = make_env(meta["env"])
    files = sorted(f for pool in ("N", "U") for f in (rec / pool).glob("plan_*.npz"))
    assert files, "no committed chunk"
    for f in files[:: max(1, len(files) // 4)]:  # a few chunks, spread over the record
        lo, hi = map(int, re.fullmatch(r"plan_(\d+)_(\d+)\.npz", f.name).groups())
        z = np.load(f)
        q, paths, n, st = z["queries"], z["paths"], z["lengths"], z["status"]
        assert len(q) == hi - lo and paths.shape[:2][0] == len(q)
        assert set(np.unique(st)) <= {int(s) for s in PlanStatus}
        ok = np.flatnonzero(st == PlanStatus.SOLVED)
        assert len(ok) > 0.9 * len(q)
        for i in ok:
            p = paths[i, : n[i]].astype(np.float32)
            assert n[i] >= 2 and np.isnan(paths[i, n[i] :]).all()
            assert np.allclose(p[0], q[i, 0], atol=1e-4) and np.allclose(p[-1], q[i, 1], atol=1e-4)
            assert np.asarray(env.steer_to(p[:-1], p[1:], padding=meta["padding"])).all(), (f, i)
            cost = float(np.asarray(env.distance(p[:-1], p[1:]), np.float64).sum())
            assert abs(cost - float(z["costs"][i])) <= 1e-3 * max(1.0, cost), (f, i)


def test_a_direct_connection_stays_its_two_ends_when_resampled():
    """BIT* returns a trivial query's path as its two ends (every trivial query of the rigid/0
    record); a spacing mode keeps it so (one includeData sample) and resamples the others."""
    env = Env.from_json(WALLS)
    q = np.array([[[1, 1], [1, 9]], [[1, 1], [9, 9]], [[9, 1], [9, 8]]], np.float32)
    trivial = np.asarray(env.steer_to(q[:, 0], q[:, 1], padding=env.padding))
    assert trivial.tolist() == [True, False, True]
    _, cut = _plan_modes(env, q, "astar", resolution=0.25)
    assert cut.lengths.tolist()[0] == 2 and cut.lengths[2] == 2 and cut.lengths[1] > 2
    res, info = shape_paths(env, cut, 0.5, "astar", env.padding)
    assert res.lengths[0] == 2 and res.lengths[2] == 2  # 8 and 7 apart: not resampled
    np.testing.assert_array_equal(res.path(0), q[0])
    assert res.lengths[1] > cut.lengths[1] and info["resample_kept"] == 0
    pr = res.path(1)
    assert (distances(env.robot, pr[:-1], pr[1:]) <= 0.5 * (1 + 1e-5)).all()
    samples = include_data(env, res.paths[[0]], res.lengths[[0]], prune=False, padding=env.padding)
    assert len(samples[2]) == 1  # one sample: start -> goal
