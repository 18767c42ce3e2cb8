"""The Panda through the whole experiment pipeline at tiny size (issue 49): D0..D3 by the
roadmap planner, four PNets for 7-D states, the neural planner's evaluation, the report.

configs/panda_small.yaml with tiny overrides on MotionBenchMaker's box scene (cuboids
only: the cheapest programs to compile). Compiling the arm's checks is most of the
run's time (seconds a program), so the overrides keep their programs few: the
discretised check for the data paths and at evaluation (the certified data check is
tested in test_data_paths, the certified check of the neural planner's check stage
below, on a planar arm), no replanning, and 220 milestones, whose edges are checked in
the chunk the non-trivial sampler's checks already compiled
(``planners.verify.ARM_CHUNKS``); the neural planner's checks run on those programs too
(``ntq_jax.neural.host_stages``), so it compiles only its coarse plan. Asserts what the run made:
every dataset's queries and paths are 7-D, each solved path runs from its query's start
to its goal with waypoints at most ``planner.data_paths`` apart (a direct connection
stays its two ends) and every segment free by the environment's check; D0..D3 hold K_train
queries each, D0 uniform, D2 and D3
non-trivial, D3 no more samples than D2; the table has PNet_0..PNet_3 on both query kinds.
"""

import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ntq_jax as nj
from ntq_jax.data import load_datasets
from ntq_jax.experiment.pipeline import load_config, prepare_run, run_pipeline
from ntq_jax.neural.motions import segments, steer

ROOT = Path(__file__).resolve().parents[1]
ENV = "panda/box/1"
K = 6
TINY = [
    f"envs=[{ENV}]",
    f"data.k_train={K}",
    "data.gamma_queries=500",
    "planner.milestones=220",
    "planner.data_check=discretized",
    "planner.grow_rounds=0",
    "model.hidden=[16,16]",
    "train.epochs=1",
    "eval.k_test=4",
    "eval.n_plan=8",
    "eval.replan_rounds=0",
    "eval.motion_check=discretized",
    "eval.ensemble=[]",
    "eval.gamma_queries=500",
]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    cfg = load_config(ROOT / "configs" / "panda_small.yaml", TINY)
    out = tmp_path_factory.mktemp("panda") / "run"
    run_pipeline(cfg, prepare_run(cfg, out), progress=False, figures=False, log=lambda _: None)
    return out, cfg


def test_datasets_hold_valid_7d_paths(run):
    out, cfg = run
    env = nj.make_env(ENV)
    (env_dir,) = (out / "data").iterdir()
    ds = load_datasets(env_dir)
    assert len(ds) == 4
    spacing = cfg.planner.data_paths_for(ENV)
    for i, d in enumerate(ds):
        assert d.queries.shape == (K, 2, 7) and d.inputs.shape[1] == 14
        assert d.targets.shape[1] == 7 and len(d.inputs) == len(d.targets)
        for j, p in enumerate(np.flatnonzero(d.solved)):  # paths: the solved queries' in order
            path = d.paths[j, : int(d.path_lengths[j])]
            assert path.shape[1] == 7 and len(path) >= 2
            np.testing.assert_array_equal(path[0], d.queries[p, 0])
            np.testing.assert_array_equal(path[-1], d.queries[p, 1])
            step = np.linalg.norm(np.diff(path, axis=0), axis=1)
            # a direct connection stays its two ends (BIT*'s), the others are resampled
            assert len(path) == 2 or step.max() <= spacing * (1 + 1e-5), (i, p, step.max())
            assert np.asarray(env.steer_to(path[:-1], path[1:])).all(), (i, p)
    kinds = [np.asarray(d.query_kind) for d in ds]
    assert (kinds[0] == 0).all() and (kinds[2] != 0).all() and (kinds[3] != 0).all()
    assert len(ds[3].inputs) <= len(ds[2].inputs)
    assert ds[0].solved.sum() >= K // 2 and ds[2].solved.sum() >= K // 2


def test_table_has_the_four_pnets(run):
    out, cfg = run
    rows = json.loads((out / "results.json").read_text())["rows"]
    assert {(r["model"], r["query_kind"]) for r in rows} == {
        (f"PNet_{m}", k) for m in range(4) for k in ("uniform", "nontrivial")
    }
    for r in rows:
        assert r["task"] == "serial_arm" and r["env"] == ENV and r["k_test"] == 4
        assert 0.0 <= r["success_ratio"] <= 1.0
        z = np.load(out / r["paths_file"])
        assert z["queries"].shape == (4, 2, 7) and z["paths"].shape[2] == 7
    assert "PNet_3" in (out / "tables.md").read_text()


def test_gathered_certified_segments_equal_the_whole_buffer():
    """neural.motions.segments checks only the existing segments with the certified check
    (gathered, in chunks): the same answers as checking the whole masked buffer. On the
    point robot, whose certified check is cheap to compile; the gathering is the robot's
    business nowhere."""
    env = nj.make_env("point/0")
    rng = np.random.default_rng(0)
    n_paths, length = 48, 12
    p = (
        rng.uniform(0, 20, (n_paths, 1, 2))
        + np.cumsum(rng.uniform(-2, 2, (n_paths, length, 2)), axis=1)
    ).astype(np.float32)
    n = rng.integers(1, length + 1, n_paths).astype(np.int32)
    mask = rng.random(n_paths) < 0.8

    def whole(p, n, m):
        seg = (jnp.arange(length - 1)[None, :] < (n - 1)[:, None]) & m[:, None]
        free = steer(
            env.robot,
            env.world,
            p[:, :-1].reshape(-1, 2),
            p[:, 1:].reshape(-1, 2),
            0.0,
            seg.reshape(-1),
            "certified",
        )
        return free.reshape(n_paths, length - 1), seg

    got, seg = jax.jit(
        lambda p, n, m: segments(env.robot, env.world, p, n, 0.0, m, "certified", chunk=64)
    )(p, n, mask)
    want, _ = jax.jit(whole)(p, n, mask)
    assert 0 < int(np.sum(np.asarray(got))) < int(np.sum(np.asarray(seg)))  # both answers occur
    np.testing.assert_array_equal(np.asarray(got), np.asarray(want))


def test_benchmark_problems_as_a_third_query_kind(run, tmp_path):
    """The scene's MotionBenchMaker problems, each in its own world, planned by every PNet
    (the run's, stand-ins here for speed: one that steps straight to the goal, one that
    never moves): each success is a path proven free by the evaluation's check from the
    problem's start to its goal; the file is reused on a rerun; the summary counts match."""
    from ntq_jax.experiment import problems

    out, cfg = run
    straight = lambda key, c, g: g  # noqa: E731
    still = lambda key, c, g: c  # noqa: E731
    got = problems.evaluate_problems(
        ENV, [straight, still], cfg, tmp_path, numbers=[1, 2], peers=(), log=lambda _: None
    )
    assert got["neural_success"].shape == (2, 2) and got["valid"].all()
    assert not got["neural_success"][1].any()  # a PNet that never moves solves nothing
    for i, n in enumerate([1, 2]):
        env = nj.make_env(f"panda/box/{n}")
        direct = bool(np.asarray(env.steer_to(env.query[:1], env.query[1:]))[0])
        # the straight PNet's plan is the direct motion (steerTo first, then its step)
        assert bool(got["neural_success"][0, i]) == direct
    again = problems.evaluate_problems(
        ENV, [straight, still], cfg, tmp_path, numbers=[1, 2], peers=(), log=None
    )
    assert again["fingerprint"] == got["fingerprint"]
    s = problems.summarize(got, ["PNet_0", "PNet_1"], 2.0)
    assert s["models"]["PNet_1"]["solved"] == 0 and s["valid"] == 2
    assert s["models"]["PNet_best-of-2"]["solved"] == int(got["neural_success"][0].sum())
