"""Dataset generation (Alg. 2 and 4), the on-disk format, resume and determinism.

Independent checks use shapely as the geometry oracle for the point robot
(a segment collides when it comes within ``padding`` of an obstacle, the
package's closed-set definition) and a plain Python loop of Alg. 4.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
import scipy.stats
from shapely.geometry import LineString, Point, box

from ntq_jax import PlanResult, data, make_env, plan
from ntq_jax.data import DatasetError
from ntq_jax.envs import Env
from ntq_jax.experiment import config as C

REPO = Path(__file__).resolve().parents[1]
K = 300  # queries per dataset in the main fixture
TOL = 1e-4  # geometric slack of the oracle (float32 kernels vs float64 shapely)


def small_config(**data_overrides) -> C.Config:
    sets = {
        "data.k_train": K,
        "data.chunk": 64,
        "data.gamma_queries": 200_000,
        "data.gamma_eval": False,
    }
    sets.update({f"data.{k}": v for k, v in data_overrides.items()})
    return C.load(None, [f"{k}={json.dumps(v)}" for k, v in sets.items()])


@pytest.fixture(scope="module")
def point_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("data")
    env = make_env("point/0")
    summary = data.generate_datasets(
        env,
        C.data_options(small_config(), "point/0"),
        out,
        env_name="point/0",
        planner="visgraph",
        progress=False,
    )
    ds = data.load_datasets(out / "point_0")
    return env, out / "point_0", summary, ds


def _obstacles(env: Env):
    spec = env.to_json()
    geoms = [box(cx - hw, cy - hh, cx + hw, cy + hh) for cx, cy, hw, hh in spec["boxes"]]
    geoms += [Point(cx, cy).buffer(r, 256) for cx, cy, r in spec["discs"]]
    return geoms


def _oracle_clearance(env: Env, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Float64 distance from each segment a-b to the nearest obstacle (shapely)."""
    obs = _obstacles(env)
    out = np.full(len(a), np.inf)
    for i, (p, q) in enumerate(zip(a.astype(float), b.astype(float))):
        seg = LineString([p, q]) if np.any(p != q) else Point(p)
        out[i] = min((seg.distance(o) for o in obs), default=np.inf)
    return out


# ---------------------------------------------------------------------------
# includeData (Alg. 4)
# ---------------------------------------------------------------------------


def _alg4_reference(env, paths, lengths, prune, padding):
    inputs, targets, pidx = [], [], []
    for p, (path, n) in enumerate(zip(paths, lengths)):
        for i in range(n - 1):
            cur, goal, nxt = path[i], path[n - 1], path[i + 1]
            if prune and bool(env.steer_to(cur[None], goal[None], padding=padding)[0]):
                continue
            inputs.append(np.concatenate([cur, goal]))
            targets.append(nxt)
            pidx.append(p)
    d = env.dim
    return (
        np.asarray(inputs, np.float32).reshape(-1, 2 * d),
        np.asarray(targets, np.float32).reshape(-1, d),
        np.asarray(pidx, np.int32),
    )


def test_include_data_matches_the_sequential_algorithm(point_run):
    env, _, _, ds = point_run
    d2 = ds[2]
    paths, lengths = np.asarray(d2.paths[:40]), np.asarray(d2.path_lengths[:40])
    for prune in (False, True):
        got = data.include_data(env, paths, lengths, prune=prune, padding=env.padding)
        want = _alg4_reference(env, paths, lengths, prune, env.padding)
        for g, w in zip(got, want):
            assert g.dtype == w.dtype and np.array_equal(g, w)


def test_include_data_prunes_exactly_the_visible_waypoints():
    # one wall; path (1,5) -> (5,9) -> (9,5): the start cannot see the goal, the corner can
    env = Env.from_json(
        {
            "name": "wall",
            "robot": {"kind": "point"},
            "bounds": [[0, 10], [0, 10]],
            "boxes": [[5, 3, 0.5, 3]],
            "padding": 0.0,
        }
    )
    paths = np.array([[[1, 5], [5, 9], [9, 5]], [[1, 1], [2, 2], [np.nan, np.nan]]], np.float32)
    inp, tgt, pidx = data.include_data(env, paths, [3, 2], prune=False)
    assert inp.shape == (3, 4) and pidx.tolist() == [0, 0, 1]
    assert np.array_equal(tgt, [[5, 9], [9, 5], [2, 2]])
    inp, tgt, pidx = data.include_data(env, paths, [3, 2], prune=True)
    assert np.array_equal(inp, [[1, 5, 9, 5]]) and np.array_equal(tgt, [[5, 9]])
    assert pidx.tolist() == [0]
    # empty input is fine
    inp, tgt, pidx = data.include_data(env, np.zeros((0, 0, 2), np.float32), [], prune=True)
    assert inp.shape == (0, 4) and tgt.shape == (0, 2) and pidx.shape == (0,)


# ---------------------------------------------------------------------------
# The generated datasets: independent checks
# ---------------------------------------------------------------------------


def test_layout_and_metadata(point_run):
    env, env_dir, summary, ds = point_run
    assert (env_dir / "env.json").is_file() and (env_dir / "figure.png").stat().st_size > 1000
    assert json.loads((env_dir / "env.json").read_text()) == env.to_json()
    assert not (env_dir / ".work").exists()
    assert sorted(p.name for p in env_dir.iterdir() if p.is_dir()) == ["D0", "D1", "D2", "D3"]
    for i, d in enumerate(ds):
        m = d.meta
        assert (m["p_nt"], m["prune"]) == [(0.0, False), (0.5, False), (1.0, False), (1.0, True)][i]
        assert m["planner"]["name"] == "visgraph" and m["seed"] == 0 and m["env"] == "point/0"
        assert m["stats"]["queries"] == K == len(d.queries)
        assert m["stats"]["samples"] == len(d.inputs)
        assert m["stats"]["solved"] == int(d.solved.sum()) == len(d.paths)
        assert 0 <= m["gamma_nt"]["gamma"] <= 1 and m["gamma_nt"]["padding"] == env.padding
        assert m["gamma_nt_eval"]["gamma"] is None  # gamma_eval: false
        assert isinstance(d.inputs, np.memmap)
        assert d.solved.mean() > 0.95  # point/0 is connected at its padding
    assert summary["planned_queries"] < 4 * K  # planning is shared


def test_every_d3_sample_is_blocked_under_the_pruning_geometry(point_run):
    env, _, _, ds = point_run
    d3 = ds[3]
    pad = d3.meta["prune_padding"]
    assert pad == env.padding and len(d3.inputs) > 0
    cur, goal = np.asarray(d3.inputs[:, :2]), np.asarray(d3.inputs[:, 2:])
    assert not np.any(np.asarray(env.steer_to(cur, goal, padding=pad)))
    # oracle: each (current, goal) segment comes within the padding of an obstacle
    assert np.all(_oracle_clearance(env, cur, goal) <= pad + TOL)
    # D3 is D2 minus exactly the samples whose (current, goal) is free
    d2 = ds[2]
    free = np.asarray(env.steer_to(d2.inputs[:, :2], d2.inputs[:, 2:], padding=pad))
    assert np.array_equal(np.asarray(d2.inputs)[~free], np.asarray(d3.inputs))
    assert d3.meta["stats"]["fraction_pruned"] == pytest.approx(free.mean())


def test_every_non_trivial_query_is_blocked(point_run):
    env, _, _, ds = point_run
    for d in ds:
        q = np.asarray(d.queries)
        nt = np.asarray(d.query_kind) == 1
        if d.meta["p_nt"] > 0:
            assert nt.sum() > 0
        else:
            assert nt.sum() == 0
        assert not np.any(np.asarray(env.steer_to(q[nt, 0], q[nt, 1])))
        assert np.all(_oracle_clearance(env, q[nt, 0], q[nt, 1]) <= env.padding + TOL)
        assert np.all(np.asarray(env.is_valid(q.reshape(-1, 2))))


def test_targets_are_the_next_waypoints(point_run):
    _, _, _, ds = point_run
    for d in ds:
        paths, lens = np.asarray(d.paths), np.asarray(d.path_lengths)
        pidx = np.asarray(d.path_index)
        cur, goal, tgt = d.inputs[:, :2], d.inputs[:, 2:], np.asarray(d.targets)
        # the goal is the path's last waypoint
        assert np.array_equal(goal, paths[pidx, lens[pidx] - 1])
        # the current state is waypoint i of that path and the target waypoint i + 1
        L = paths.shape[1]
        match = np.all(paths[pidx, : L - 1] == cur[:, None, :], axis=2) & np.all(
            paths[pidx, 1:] == tgt[:, None, :], axis=2
        )
        assert np.all(match.any(axis=1))
        if not d.meta["prune"]:
            assert len(d.inputs) == int((lens - 1).sum())
        # samples are in path order
        assert np.all(np.diff(pidx) >= 0)


def test_stored_paths_are_collision_free_and_solve_their_queries(point_run):
    env, _, _, ds = point_run
    for d in ds:
        paths, lens = np.asarray(d.paths), np.asarray(d.path_lengths)
        q = np.asarray(d.queries)[np.asarray(d.solved)]
        rows = np.arange(len(lens))
        assert np.array_equal(paths[:, 0], q[:, 0])
        assert np.array_equal(paths[rows, lens - 1], q[:, 1])
        inside = np.arange(paths.shape[1])[None] < lens[:, None]
        assert np.all(np.isfinite(paths[inside])) and np.all(np.isnan(paths[~inside]))
        p, i = np.nonzero(np.arange(paths.shape[1] - 1)[None] < (lens - 1)[:, None])
        a, b = paths[p, i], paths[p, i + 1]
        assert np.all(np.asarray(env.steer_to(a, b)))
        assert np.all(_oracle_clearance(env, a, b) >= env.padding - TOL)


def test_d0_non_trivial_fraction_matches_gamma_nt(point_run):
    env, _, _, ds = point_run
    g = ds[0].meta["gamma_nt"]
    lo, hi = g["ci95"]
    frac = ds[0].meta["stats"]["blocked_fraction"]
    q = np.asarray(ds[0].queries)
    assert frac == pytest.approx(1 - np.asarray(env.steer_to(q[:, 0], q[:, 1])).mean())
    # a binomial(K, gamma) fraction: within 4 sigma of the gamma interval
    sigma = np.sqrt(g["gamma"] * (1 - g["gamma"]) / K)
    assert lo - 4 * sigma <= frac <= hi + 4 * sigma
    assert ds[2].meta["stats"]["blocked_fraction"] == 1.0


def test_query_distribution_of_every_dataset_is_alg2(point_run):
    """Shared pools keep each dataset's marginal: compare with fresh, independent Alg. 2 draws."""
    import jax

    env, _, _, ds = point_run
    d0, d1, d2, d3 = ds
    # sharing structure
    assert np.array_equal(d3.queries, d2.queries) and np.array_equal(
        d3.paths, d2.paths, equal_nan=True
    )
    k1 = np.asarray(d1.query_kind)
    nt, un = k1 >= 1, k1 == 0
    assert np.array_equal(d1.queries[un], d0.queries[: un.sum()])
    assert np.array_equal(d1.queries[nt], d2.queries[: nt.sum()])
    assert d1.meta["sharing"]["uniform_pool"] == [0, int(un.sum())]
    # the mixture count is Binomial(K, 1/2)
    assert scipy.stats.binomtest(int(nt.sum()), K, 0.5).pvalue > 1e-3
    # each dataset vs independent draws of its own Alg. 2 distribution
    for i, d in enumerate(ds[:3]):
        p = d.meta["p_nt"]
        ref, _ = env.sample_queries(jax.random.PRNGKey(1000 + i), 2000, p)
        q = np.asarray(d.queries)
        for name, f in [
            ("start x", lambda x: x[:, 0, 0]),
            ("goal y", lambda x: x[:, 1, 1]),
            ("distance", lambda x: np.linalg.norm(x[:, 0] - x[:, 1], axis=1)),
        ]:
            pv = scipy.stats.ks_2samp(f(q), f(ref)).pvalue
            assert pv > 1e-3, (d.meta["name"], name, pv)
        blk = 1 - np.asarray(env.steer_to(q[:, 0], q[:, 1])).mean()
        blk_ref = 1 - np.asarray(env.steer_to(ref[:, 0], ref[:, 1])).mean()
        assert abs(blk - blk_ref) < 4 * np.sqrt(0.25 / K + 0.25 / 2000) + 1e-9


# ---------------------------------------------------------------------------
# Edge cases: empty D3, corrupt files
# ---------------------------------------------------------------------------


def straight_line(env, queries, *, padding, seed=0):
    """A fake planner: the straight segment (valid on an obstacle-free map)."""
    q = np.asarray(queries, np.float32)
    k = len(q)
    return PlanResult(
        q.copy(),
        np.full(k, 2, np.int32),
        np.linalg.norm(q[:, 1] - q[:, 0], axis=1),
        np.zeros(k, np.int8),
        {},
    )


def test_obstacle_free_map_gives_an_empty_valid_d3(tmp_path):
    env = Env.from_json(
        {"name": "empty", "robot": {"kind": "point"}, "bounds": [[0, 10], [0, 10]], "padding": 0.5}
    )
    cfg = C.load(None, ["data.k_train=12", "data.gamma_queries=1000", "sampling.n_max=20"])
    with pytest.warns(RuntimeWarning, match="pruning removed every segment"):
        s = data.generate_datasets(
            env,
            C.data_options(cfg, env.name),
            tmp_path,
            planner=straight_line,
            progress=False,
            figure=False,
        )
    assert s["datasets"]["D3"]["samples"] == 0
    d0, d1, d2, d3 = data.load_datasets(s["env_dir"])  # <out>/empty-<content hash>
    assert d3.inputs.shape == (0, 4) and d3.targets.shape == (0, 2) and d3.path_index.shape == (0,)
    assert len(d3.paths) == 12 and any("pruning removed every" in w for w in d3.meta["warnings"])
    assert np.all(np.asarray(d2.query_kind) == 2)  # the non-trivial sampler was exhausted
    assert d2.meta["stats"]["nt_exhausted"] == 12 and d0.meta["gamma_nt"]["gamma"] == 0.0
    assert len(d0.inputs) == 12  # without pruning: one sample per straight path


def test_a_custom_planners_paths_are_verified_and_bad_ones_recorded_unsolved(tmp_path):
    """The straight segment through a wall fails verification: unsolved, counted, warned."""
    env = Env.from_json(
        {
            "name": "wall",
            "robot": {"kind": "point"},
            "bounds": [[0, 10], [0, 10]],
            "boxes": [[5, 5, 0.5, 4]],
            "padding": 0.0,
        }
    )
    cfg = C.load(None, ["data.k_train=40", "data.gamma_queries=1000", "data.gamma_eval=false"])
    returned = []

    def keep(env, queries, *, padding, seed=0):
        res = straight_line(env, queries, padding=padding, seed=seed)
        returned.append((res, res.paths.copy(), res.status.copy()))
        return res

    with pytest.warns(RuntimeWarning, match="failed the independent check"):
        s = data.generate_datasets(
            env, C.data_options(cfg, env.name), tmp_path, planner=keep, progress=False, figure=False
        )
    for res, paths, status in returned:  # the planner's arrays are not modified
        assert np.array_equal(res.paths, paths) and np.array_equal(res.status, status)
    for d in data.load_datasets(s["env_dir"]):  # <out>/wall-<content hash>
        q = np.asarray(d.queries)
        free = np.asarray(env.steer_to(q[:, 0], q[:, 1]))
        assert np.array_equal(np.asarray(d.solved), free)
        assert d.meta["stats"]["rejected_paths"] == int((~free).sum())
        assert s["datasets"][d.meta["name"]]["unsolved"] == int((~free).sum())
    assert s["datasets"]["D2"]["rejected_paths"] == 40  # every non-trivial query is blocked


@pytest.fixture()
def copy_d3(point_run, tmp_path):
    import shutil

    _, env_dir, _, _ = point_run
    dst = tmp_path / "D3"
    shutil.copytree(env_dir / "D3", dst)
    return dst


def test_truncated_array_raises_dataset_error(copy_d3):
    f = copy_d3 / "inputs.npy"
    f.write_bytes(f.read_bytes()[:-17])
    with pytest.raises(DatasetError, match=r"inputs\.npy.*corrupt.*generate_data"):
        data.load_dataset(copy_d3)
    with pytest.raises(DatasetError, match=r"inputs\.npy.*truncated"):
        data.load_dataset(copy_d3, verify=False)


def test_flipped_byte_raises_dataset_error(copy_d3):
    f = copy_d3 / "targets.npy"
    b = bytearray(f.read_bytes())
    b[-3] ^= 0x40
    f.write_bytes(bytes(b))
    with pytest.raises(DatasetError, match=r"targets\.npy: corrupt"):
        data.load_dataset(copy_d3)


def test_missing_files_raise_dataset_error(copy_d3):
    (copy_d3 / "paths.npy").unlink()
    with pytest.raises(DatasetError, match=r"paths\.npy: missing"):
        data.load_dataset(copy_d3)
    (copy_d3 / "meta.json").write_text("{not json")
    with pytest.raises(DatasetError, match=r"meta\.json: not valid JSON"):
        data.load_dataset(copy_d3)
    (copy_d3 / "meta.json").unlink()
    with pytest.raises(DatasetError, match=r"incomplete"):
        data.load_dataset(copy_d3)
    assert issubclass(DatasetError, ValueError)


def test_wrong_dtype_raises_dataset_error(copy_d3):
    meta = json.loads((copy_d3 / "meta.json").read_text())
    np.save(copy_d3 / "path_index.npy", np.zeros(meta["arrays"]["path_index"]["shape"], np.int64))
    with pytest.raises(DatasetError, match=r"path_index\.npy: dtype int64"):
        data.load_dataset(copy_d3, verify=False)


# ---------------------------------------------------------------------------
# kill -9, resume, determinism
# ---------------------------------------------------------------------------

_CHILD = textwrap.dedent("""
    import json, sys, time
    import numpy as np
    from ntq_jax import data, make_env, plan
    from ntq_jax.experiment import config as C

    def slow_visgraph(env, queries, *, padding, seed=0):
        time.sleep(float(sys.argv[3]))
        return plan(env, queries, "visgraph", padding=padding, seed=seed)

    cfg = C.load(None, ["data.k_train=40", f"data.chunk={sys.argv[2]}",
                        "data.gamma_queries=20000", "data.gamma_eval=false"])
    s = data.generate_datasets(make_env("point/0"), C.data_options(cfg, "point/0"),
                               sys.argv[1], env_name="point/0",
                               planner=slow_visgraph, progress=False, figure=False)
    print("SUMMARY" + json.dumps({k: s[k] for k in ("reused_queries", "skipped")}))
""")


def _child(out, chunk, sleep):
    return subprocess.Popen(
        [sys.executable, "-c", _CHILD, str(out), str(chunk), str(sleep)],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=dict(os.environ, JAX_PLATFORMS="cpu"),
    )


def _arrays(env_dir: Path) -> dict[str, bytes]:
    return {f"{p.parent.name}/{p.name}": p.read_bytes() for p in sorted(env_dir.glob("D*/*.npy"))}


def test_kill9_resume_is_byte_identical_to_an_uninterrupted_run(tmp_path):
    killed = tmp_path / "killed"
    proc = _child(killed, 8, 0.4)  # 80 pooled queries in 10 chunks of 8, 0.4 s each
    work = killed / "point_0" / ".work"
    t0 = time.time()
    while time.time() - t0 < 120:
        if len(list(work.glob("*/plan_*.npz"))) >= 3 or proc.poll() is not None:
            break
        time.sleep(0.02)
    assert proc.poll() is None, (
        "the child finished before it could be killed: " + proc.stderr.read()
    )
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    done = len(list(work.glob("*/plan_*.npz")))
    assert 3 <= done < 10
    assert not (killed / "point_0" / "D0" / "meta.json").exists()  # nothing looks complete
    # resume (in this process, with a different chunk size): completed chunks are reused
    calls = []

    def slow_visgraph(env, queries, *, padding, seed=0):  # the child's name: same fingerprint
        calls.append(len(queries))
        return plan(env, queries, "visgraph", padding=padding, seed=seed)

    cfg5 = C.load(
        None,
        ["data.k_train=40", "data.chunk=5", "data.gamma_queries=20000", "data.gamma_eval=false"],
    )
    summary = data.generate_datasets(
        make_env("point/0"),
        C.data_options(cfg5, "point/0"),
        killed,
        env_name="point/0",
        planner=slow_visgraph,
        progress=False,
        figure=False,
    )
    assert summary["reused_queries"] == 8 * done and not summary["skipped"]
    assert sum(calls) == summary["planned_queries"] - 8 * done  # nothing planned twice
    # an uninterrupted run in this process, chunk size 13
    cfg = C.load(
        None,
        ["data.k_train=40", "data.chunk=13", "data.gamma_queries=20000", "data.gamma_eval=false"],
    )
    data.generate_datasets(
        make_env("point/0"),
        C.data_options(cfg, "point/0"),
        tmp_path / "clean",
        env_name="point/0",
        planner=slow_visgraph,
        progress=False,
        figure=False,
    )
    a, b = _arrays(killed / "point_0"), _arrays(tmp_path / "clean" / "point_0")
    assert len(a) == 4 * 8 and a.keys() == b.keys()
    for k in a:
        assert a[k] == b[k], k
    for nm in ("D0", "D3"):
        ma = json.loads((killed / "point_0" / nm / "meta.json").read_text())
        mb = json.loads((tmp_path / "clean" / "point_0" / nm / "meta.json").read_text())
        assert ma["stats"] == mb["stats"] and ma["arrays"] == mb["arrays"]
    # a rerun of a complete output does nothing
    again = data.generate_datasets(
        make_env("point/0"),
        C.data_options(cfg, "point/0"),
        tmp_path / "clean",
        env_name="point/0",
        planner=slow_visgraph,
        progress=False,
        figure=False,
    )
    assert again["skipped"]


def test_loader_refuses_a_half_written_dataset(point_run, tmp_path):
    """A folder whose arrays were replaced after meta.json (an interrupted rewrite) is refused."""
    import shutil

    _, env_dir, _, _ = point_run
    shutil.copytree(env_dir / "D1", tmp_path / "D1")
    shutil.copy(env_dir / "D2" / "inputs.npy", tmp_path / "D1" / "inputs.npy")
    with pytest.raises(DatasetError, match=r"D1.*inputs\.npy"):
        data.load_dataset(tmp_path / "D1")


def test_cli_generates_and_rejects_a_bad_key(tmp_path):
    sys.path.insert(0, str(REPO / "scripts"))
    import generate_data

    rc = generate_data.main(
        [
            "--env",
            "point/0",
            "--out",
            str(tmp_path / "out"),
            "--no-progress",
            "--planner",
            "visgraph",
            "--set",
            "data.k_train=20",
            "--set",
            "data.gamma_queries=5000",
            "--set",
            "data.gamma_eval=false",
            "--no-figure",
            "--no-compile-cache",
        ]
    )
    assert rc == 0
    ds = data.load_datasets(tmp_path / "out" / "point_0")
    assert [len(d.queries) for d in ds] == [20] * 4
    assert generate_data.main(["--set", "data.k_trian=3"]) == 2


def test_custom_dataset_specs_share_pools_by_prefix(tmp_path):
    """Any list of (p_nt, prune): equal specs share their queries, all draw pool prefixes."""
    env = make_env("point/0")
    cfg = C.load(
        None,
        [
            "data.k_train=50",
            "data.chunk=64",
            "data.gamma_queries=20000",
            "data.gamma_eval=false",
            "data.datasets=[{p_nt: 0.3}, {p_nt: 0.3, prune: true}, {p_nt: 0.8}]",
        ],
    )
    s = data.generate_datasets(
        env,
        C.data_options(cfg, env.name),
        tmp_path,
        planner="visgraph",
        progress=False,
        figure=False,
    )
    a, b, c = data.load_datasets(tmp_path / "point_0")
    assert b.meta["sharing"]["same_queries_as"] == ["D0"]
    assert np.array_equal(a.queries, b.queries)
    free = np.asarray(env.steer_to(a.inputs[:, :2], a.inputs[:, 2:]))
    assert np.array_equal(np.asarray(a.inputs)[~free], np.asarray(b.inputs))
    for x, y in ((a, c), (c, a)):
        for kinds in ((0,), (1, 2)):
            mx = np.isin(np.asarray(x.query_kind), kinds)
            my = np.isin(np.asarray(y.query_kind), kinds)
            n = min(mx.sum(), my.sum())
            assert np.array_equal(x.queries[mx][:n], y.queries[my][:n])
    n_nt = [int((np.asarray(d.query_kind) >= 1).sum()) for d in (a, c)]
    assert n_nt[0] < n_nt[1]
    assert s["planned_queries"] == max(50 - n for n in n_nt) + max(n_nt)
