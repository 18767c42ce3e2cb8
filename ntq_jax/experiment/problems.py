"""A benchmark's own problems as a third kind of test query (MotionBenchMaker's, the Panda).

The PNets of a Panda run are trained on one MotionBenchMaker problem's world (the paper
trains per map: ``panda/<scene>/<n>`` is problem ``n``'s obstacles). MotionBenchMaker's
100 problems of that scene place the same obstacles at other poses, each with its own
start and goal. This stage asks how often each PNet solves them, each in its own world,
beside classical planners given a time budget: a measure of how far a per-map PNet
carries over to the poses of its scene, next to what the benchmark's planners achieve.

For every problem of the scene (:func:`ntq_jax.scenes.mbm.load_scene`, one
:class:`ntq_jax.Env` each):

* every PNet plans its start and goal with the evaluation's options
  (:func:`ntq_jax.experiment.config.neural_options`, steerTo on; success is a path
  proven free by ``eval.motion_check``), all members in one batch
  (:func:`ntq_jax.neural.plan_members`) with a key of the problem's number;
  ``PNet_best-of-<M>`` keeps each problem's cheapest success of the members;
* each peer of :data:`PEERS` that is installed plans it: OMPL's RRT-Connect with
  simplification (``"rrtconnect"``, in this process on the package's discretised checks)
  at ``planner.eval_time_budget`` seconds, and VAMP (``"vamp"``, only where it is built;
  it has no time budget, it stops at its own iteration limit). Their
  paths are discretised-checked as the peers plan them; whether each also passes
  ``eval.motion_check`` is recorded apart (``certified``), with each problem's solve time,
  so a reader can compare at the neural planner's own time per problem as well.

A problem whose start or goal is in collision at padding 0 is ``valid = False`` and
counts for no one. The arrays are saved in ``<out_dir>/problems.npz`` (fingerprinted:
a rerun with the same inputs loads it) and :func:`summarize` makes the compact summary
that a results folder keeps (``problems.json``).
"""

from __future__ import annotations

import importlib.util
import time
from pathlib import Path
from typing import Callable

import jax
import numpy as np

from ntq_jax import artifacts
from ntq_jax import neural as NP
from ntq_jax.experiment import config as C
from ntq_jax.neural.options import ALGORITHM_VERSION
from ntq_jax.planners import plan
from ntq_jax.planners.verify import check_paths, valid_queries
from ntq_jax.stats import wilson_interval

__all__ = [
    "PEERS",
    "PROBLEMS_VERSION",
    "evaluate_problems",
    "peer_available",
    "scene_of",
    "summarize",
]

#: The classical planners the problems are also given to, when installed.
PEERS = ("rrtconnect", "vamp")
#: Bumped when what this stage computes changes (part of the file's fingerprint).
PROBLEMS_VERSION = 1
_TAG = 0x5EC0  # the problems' PRNG tag: no other stage folds it in

_MODULE_OF = {"rrtconnect": "ompl", "vamp": "vamp"}


def scene_of(env_name: str) -> str | None:
    """The MotionBenchMaker scene of ``panda/<scene>/<number>``, else None."""
    parts = str(env_name).split("/")
    if len(parts) == 3 and parts[0] == "panda":
        return parts[1]
    return None


def peer_available(name: str) -> bool:
    """Whether peer ``name``'s package is installed here (a folder of that name on the
    path, a namespace package without code, is not)."""
    spec = importlib.util.find_spec(_MODULE_OF[name])
    return spec is not None and spec.origin is not None


def _problem_envs(scene: str, numbers) -> list:
    from ntq_jax.envs import make_env

    return [make_env(f"panda/{scene}/{n}") for n in numbers]


def _neural(envs, pnets, cfg, log) -> dict:
    """``(M, P)`` success, costs, seconds and causes of every member on every problem."""
    opts = C.neural_options(cfg.eval, steer=True)
    m, p = len(pnets), len(envs)
    success = np.zeros((m, p), bool)
    costs = np.full((m, p), np.inf)
    seconds = np.zeros(p)
    cause = np.zeros((m, p), np.int8)
    base = jax.random.fold_in(jax.random.key(cfg.seed), _TAG)
    compile_s = 0.0
    for i, env in enumerate(envs):
        key = jax.random.fold_in(base, i + 1)
        keys = jax.numpy.stack([jax.random.fold_in(key, j) for j in range(m)])
        q = np.asarray(env.query, np.float32)[None]
        got = NP.plan_members(env, pnets, q, keys, opts, chunk=1, repair_width=1)
        for j, r in enumerate(got):
            success[j, i], costs[j, i], cause[j, i] = r.success[0], r.costs[0], r.cause[0]
        seconds[i] = got[0].seconds  # the whole batch: all members together
        compile_s += got[0].compile_seconds
        if (i + 1) % 25 == 0:
            log(f"  problems {i + 1}/{p}: success {success[:, : i + 1].mean(1).round(3).tolist()}")
    return dict(
        success=success, costs=costs, seconds=seconds, cause=cause, compile_seconds=compile_s
    )


def _budget(name: str, cfg) -> dict:
    """The time-budget option of peer ``name``: VAMP's RRT-Connect takes none (it stops at
    its own iteration limit; its solve times are recorded all the same)."""
    return {"time_budget": cfg.planner.eval_time_budget} if name == "rrtconnect" else {}


def _peer(name: str, envs, cfg) -> dict:
    """``(P,)`` outcomes of peer ``name`` (planned with its discretised check)."""
    p = len(envs)
    solved = np.zeros(p, bool)
    certified = np.zeros(p, bool)
    costs = np.full(p, np.inf)
    solve_s = np.full(p, np.nan)
    for i, env in enumerate(envs):
        q = np.asarray(env.query, np.float32)[None]
        t0 = time.perf_counter()
        res = plan(env, q, name, padding=0.0, seed=cfg.seed + i, **_budget(name, cfg))
        wall = time.perf_counter() - t0
        solved[i] = bool(res.solved[0])
        times = res.info.get("solve_times", res.info.get("vamp_times"))
        solve_s[i] = float(np.asarray(times)[0]) if times is not None else wall
        if solved[i]:
            costs[i] = res.costs[0]
            ok, _ = check_paths(env, res.paths, res.lengths, 0.0, cfg.eval.motion_check)
            certified[i] = bool(ok[0])
    return dict(solved=solved, certified=certified, costs=costs, solve_seconds=solve_s)


def evaluate_problems(
    env_name: str,
    pnets: list[Callable],
    cfg,
    out_dir,
    *,
    model_fingerprint: str = "",
    numbers=None,
    peers=PEERS,
    log: Callable[[str], None] = print,
) -> dict:
    """The arrays of the module docstring for the scene of ``env_name`` (saved, or loaded).

    Args:
        env_name: ``panda/<scene>/<number>``, the map the PNets were trained on.
        pnets: the members' PNets (:func:`ntq_jax.models.member_pnets`).
        cfg: the run's :class:`ntq_jax.experiment.config.Config`.
        out_dir: the folder of ``problems.npz``.
        model_fingerprint: identifies the PNets (part of the file's fingerprint).
        numbers: the problem numbers (default all of :data:`ntq_jax.scenes.mbm.NUMBERS`).
        peers: the peers to run (those not installed are skipped and not recorded).
        log: progress messages.

    Returns:
        ``valid (P,)``, ``numbers (P,)``, ``neural_*`` ``(M, P)`` arrays (success, costs,
        cause) and ``neural_seconds (P,)``, and per peer ``<peer>_solved``,
        ``<peer>_certified``, ``<peer>_costs``, ``<peer>_solve_seconds`` ``(P,)``.

    Raises:
        ValueError: ``env_name`` is not a MotionBenchMaker problem.
    """
    scene = scene_of(env_name)
    if scene is None:
        raise ValueError(f"{env_name} is not a MotionBenchMaker problem (panda/<scene>/<n>)")
    from ntq_jax.scenes.mbm import NUMBERS

    numbers = [int(n) for n in (NUMBERS if numbers is None else numbers)]
    ran = [p for p in peers if peer_available(p)]
    fp = artifacts.fingerprint(
        cfg.hash(),
        env_name,
        model_fingerprint,
        numbers,
        PROBLEMS_VERSION,
        ran,
        ALGORITHM_VERSION,
    )

    def compute() -> dict:
        envs = _problem_envs(scene, numbers)
        q = np.stack([np.asarray(e.query, np.float32) for e in envs])
        valid = np.array([bool(valid_queries(e, q[i : i + 1], 0.0)[0]) for i, e in enumerate(envs)])
        log(f"[{env_name}] {scene}: {len(envs)} problems ({int(valid.sum())} valid), PNets")
        out = {f"neural_{k}": v for k, v in _neural(envs, pnets, cfg, log).items()}
        for name in ran:
            limit = _budget(name, cfg).get("time_budget")
            per = f"at {limit} s per problem" if limit else "to its own iteration limit"
            log(f"[{env_name}] {scene}: {name} {per}")
            out.update({f"{name}_{k}": v for k, v in _peer(name, envs, cfg).items()})
        return dict(out, valid=valid, numbers=np.array(numbers), queries=q, peers=np.array(ran))

    return artifacts.compute_or_load(Path(out_dir) / "problems.npz", fp, compute)


def _rate(ok: np.ndarray, valid: np.ndarray) -> dict:
    k, n = int((ok & valid).sum()), int(valid.sum())
    lo, hi = wilson_interval(k, n)
    return {"solved": k, "of": n, "ratio": k / max(n, 1), "ci95": [lo, hi]}


def summarize(got: dict, model_names: list[str], budget: float) -> dict:
    """The compact summary of :func:`evaluate_problems`' arrays (JSON-ready).

    Per model (``model_names``, one per member, then ``PNet_best-of-<M>``): solved of the
    valid problems with its 95% Wilson interval, and the median seconds per problem of
    the members' batch. Per peer: solved (its own discretised check), certified, solved
    within ``budget`` and within the neural planner's median time, median solve seconds,
    and the median cost ratio of the best-of PNets to the peer on problems both solved.
    """
    valid = np.asarray(got["valid"], bool)
    succ = np.asarray(got["neural_success"], bool)
    costs = np.asarray(got["neural_costs"], float)
    best_costs = np.where(succ, costs, np.inf).min(0)
    best = np.isfinite(best_costs)
    t_neural = float(np.median(np.asarray(got["neural_seconds"])[valid]))
    models = {name: _rate(succ[j], valid) for j, name in enumerate(model_names)}
    models[f"PNet_best-of-{len(model_names)}"] = _rate(best, valid)
    out = {
        "problems": int(len(valid)),
        "valid": int(valid.sum()),
        "budget_seconds": budget,
        "neural_median_seconds": t_neural,
        "models": models,
        "peers": {},
    }
    for name in [str(p) for p in np.asarray(got.get("peers", []))]:
        solved = np.asarray(got[f"{name}_solved"], bool)
        cert = np.asarray(got[f"{name}_certified"], bool)
        t = np.asarray(got[f"{name}_solve_seconds"], float)
        both = best & cert & valid
        ratio = best_costs[both] / np.asarray(got[f"{name}_costs"], float)[both]
        out["peers"][name] = {
            "solved": _rate(solved, valid),
            "certified": _rate(cert, valid),
            "within_neural_time": _rate(solved & (t <= t_neural), valid),
            "median_solve_seconds": float(np.nanmedian(t[valid & solved]))
            if (valid & solved).any()
            else None,
            "best_cost_ratio_median": float(np.median(ratio)) if len(ratio) else None,
            "both_solved": int(both.sum()),
        }
    return out
