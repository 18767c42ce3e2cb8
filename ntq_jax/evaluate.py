"""Evaluation of a trained PNet ensemble with the neural planner (Section V of the paper).

For every environment: ``K_test`` fresh uniform and ``K_test`` fresh non-trivial
test queries (keys derived from the run seed with a tag no other stage uses, so
they are disjoint from the training queries), solved by the classical reference
planner (the task's planner on the evaluation geometry, padding 0, at the
evaluation budget) and, for point robots, by the exact visibility graph; then by
the neural planner (:mod:`ntq_jax.neural_planner`) with every ensemble member,
with and/or without steerTo (``config.eval.steer``).

Metrics per (environment, model, test query kind, steerTo):

* success ratio ``k / K_test`` with its 95% Wilson interval (a success is a path
  that reaches the goal and is collision-free on the evaluation geometry);
* cost ratio = neural cost / reference cost per query, averaged over the
  queries both solved (and the same against the visibility-graph optimum for
  point robots);
* planning time per query (batched wall time / K_test, compile time apart);
* failures by cause: ``no_path`` (goal not reached within N_plan),
  ``infeasible`` (in collision after replanning), ``invalid_query``, and
  ``reference_failed`` (queries the reference planner did not solve).

Files (all written atomically; a complete file is reused on a rerun)::

    <run>/eval/<env_slug>/queries.npz          test queries (uniform, nontrivial)
    <run>/eval/<env_slug>/reference.npz        reference (and optimum) paths and costs
    <run>/paths/<env_slug>/<model>_<uniform|nontrivial>[_nosteer].npz
        queries, paths (NaN padded), lengths, success, costs, cause, ref_costs,
        opt_costs, pnet_calls, replans, seconds, compile_seconds, fingerprint
"""

from __future__ import annotations

import hashlib
import json
import time
import zlib
from pathlib import Path
from typing import Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax.tree_util import Partial

from ntq_jax import artifacts
from ntq_jax import neural_planner as NP
from ntq_jax.types import PlanStatus
from ntq_jax.queries import wilson_interval

EVAL_TAG = 0x7E57  # key tag of the test queries (training uses other streams)
KINDS = ("uniform", "nontrivial")


def env_slug(name: str) -> str:
    """Folder name of an environment (the same rule as :func:`ntq_jax.data.env_slug`)."""
    try:
        from ntq_jax.data import env_slug as _slug
        return _slug(name)
    except ImportError:  # pragma: no cover
        return str(name).replace("/", "_")


def model_name(member: int) -> str:
    return f"PNet_{member}"


def paths_file(run_dir, slug: str, member: int, kind: str, steer: bool) -> Path:
    """``<run>/paths/<slug>/PNet_<m>_<kind>[_nosteer].npz``."""
    return Path(run_dir) / "paths" / slug / f"{model_name(member)}_{kind}{'' if steer else '_nosteer'}.npz"


# ---------------------------------------------------------------------------
# Atomic files
# ---------------------------------------------------------------------------

def load_npz(path: Path, fingerprint: str | None = None) -> dict | None:
    """The arrays of a complete ``.npz`` (None if absent, unreadable or of another run)."""
    path = Path(path)
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            out = {k: z[k] for k in z.files}
    except Exception:  # noqa: BLE001 - a corrupt or partial file is recomputed
        return None
    if fingerprint is not None and str(out.get("fingerprint", "")) != fingerprint:
        return None
    return out




# ---------------------------------------------------------------------------
# PNets from an ensemble
# ---------------------------------------------------------------------------

_APPLY: dict = {}


def member_pnets(ens) -> list[Partial]:
    """One planner-ready PNet per member: ``Partial(apply, params_m, m)``.

    Same semantics as :func:`ntq_jax.models.predictor` ``(ens, m)`` (dropout on,
    key ``fold_in(key, m)``), but the members share one apply function, so the
    neural planner compiles once for the whole ensemble.
    """
    from ntq_jax import models

    graphdef = ens.graphdef
    try:
        fn = _APPLY.get(graphdef)
    except TypeError:  # unhashable graphdef: no sharing across ensembles
        fn = None
    if fn is None:
        def fn(params, m, key, current, goal):
            return models.apply_member(graphdef, params, jax.random.fold_in(key, m), current, goal)
        try:
            _APPLY[graphdef] = fn
        except TypeError:
            pass
    return [Partial(fn, models.unstack_state(ens.params, m), jnp.uint32(m))
            for m in range(ens.num_members)]


# ---------------------------------------------------------------------------
# Test queries and references
# ---------------------------------------------------------------------------

def _tag(slug: str) -> int:
    return zlib.crc32(slug.encode()) & 0x7FFFFFFF


def test_queries(env, cfg, slug: str, out_dir: Path) -> dict[str, np.ndarray]:
    """``{"uniform": (K, 2, d), "nontrivial": (K, 2, d)}``, cached in ``queries.npz``."""
    ev = cfg.eval
    qpad = env.resolve_padding(ev.query_padding)
    fp = _fp(slug, ev.k_test, qpad, cfg.seed, cfg.sampling.n_max, env.to_json())
    f = Path(out_dir) / "queries.npz"
    got = load_npz(f, fp)
    if got is not None:
        return {k: got[k] for k in KINDS}
    key = jax.random.fold_in(jax.random.fold_in(jax.random.key(cfg.seed), EVAL_TAG), _tag(slug))
    out = {}
    for i, kind in enumerate(KINDS):
        q, _ = env.sample_queries(jax.random.fold_in(key, i), ev.k_test, float(i), padding=qpad,
                                  n_max=cfg.sampling.n_max)
        out[kind] = np.asarray(q, np.float32)
    artifacts.save_npz(f, fingerprint=fp, query_padding=qpad, **out)
    return out


def reference_plans(env, cfg, env_name: str, slug: str, queries: dict, out_dir: Path,
                    planner: Callable | None = None) -> dict:
    """Reference (and, for point robots, optimum) costs and paths on padding 0, cached."""
    name = cfg.planner.name if planner is None else getattr(planner, "__name__", "custom")
    fp = _fp(slug, name, cfg.planner, {k: v.tobytes().hex()[:64] for k, v in queries.items()},
             {k: len(v) for k, v in queries.items()})
    f = Path(out_dir) / "reference.npz"
    got = load_npz(f, fp)
    if got is not None:
        return got
    out: dict = {"fingerprint": fp, "planner": name}
    for kind in KINDS:
        q = queries[kind]
        t0 = time.perf_counter()
        res = _run_reference(env, q, cfg, env_name, planner)
        out[f"{kind}_seconds"] = time.perf_counter() - t0
        out[f"{kind}_costs"] = np.asarray(res.costs, np.float64)
        out[f"{kind}_status"] = np.asarray(res.status, np.int8)
        out[f"{kind}_paths"] = np.asarray(res.paths, np.float32)
        out[f"{kind}_lengths"] = np.asarray(getattr(res, "lengths", None) if hasattr(res, "lengths")
                                            else res.path_lengths, np.int32)
        if env.robot.kind == "point":
            opt = _visgraph(env, q)
            out[f"{kind}_opt_costs"] = np.asarray(opt.costs, np.float64)
    artifacts.save_npz(f, **out)
    return load_npz(f)


def _run_reference(env, q, cfg, env_name, planner):
    if planner is not None:
        return planner(env, q, padding=0.0, seed=cfg.seed)
    from ntq_jax.planners import plan
    pc = cfg.planner
    if pc.name == "astar":
        opts = {"resolution": pc.resolution}
    elif pc.name == "bitstar":
        budget = (pc.eval_time_budget_for(env_name) if hasattr(pc, "eval_time_budget_for")
                  else pc.eval_time_budget)
        opts = {"time_budget": budget, "workers": pc.workers}
    else:
        opts = {}
    return plan(env, q, pc.name, padding=0.0, seed=cfg.seed, **opts)


def _visgraph(env, q):
    from ntq_jax.planners.visgraph import plan_visgraph
    return plan_visgraph(env, q, padding=0.0)


def _fp(*parts) -> str:
    blob = json.dumps(parts, sort_keys=True, default=str).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


# ---------------------------------------------------------------------------
# Metrics
# ---------------------------------------------------------------------------

def metrics(success: np.ndarray, costs: np.ndarray, cause: np.ndarray, ref_costs: np.ndarray,
            ref_status: np.ndarray, opt_costs: np.ndarray | None = None) -> dict:
    """Success ratio with its Wilson interval, cost ratios and failure counts."""
    k = int(len(success))
    s = int(np.sum(success))
    lo, hi = wilson_interval(s, k)
    ref_ok = (ref_status == PlanStatus.SOLVED) & np.isfinite(ref_costs) & (ref_costs > 0)
    both = success & ref_ok
    out = {
        "k_test": k, "successes": s, "success_ratio": s / k if k else float("nan"),
        "success_ci95": [lo, hi],
        "cost_ratio": float(np.mean(costs[both] / ref_costs[both])) if both.any() else None,
        "cost_ratio_n": int(both.sum()),
        "failures": {NP.CAUSES[c]: int(np.sum(cause == c)) for c in NP.CAUSES if c != NP.SUCCESS},
        "reference_failed": int(np.sum(~(ref_status == PlanStatus.SOLVED))),
        "reference_success_ratio": float(np.mean(ref_status == PlanStatus.SOLVED)) if k else float("nan"),
    }
    if opt_costs is not None:
        ok = success & np.isfinite(opt_costs) & (opt_costs > 0)
        out["cost_ratio_opt"] = float(np.mean(costs[ok] / opt_costs[ok])) if ok.any() else None
        rk = ref_ok & np.isfinite(opt_costs) & (opt_costs > 0)
        out["reference_cost_ratio_opt"] = (float(np.mean(ref_costs[rk] / opt_costs[rk]))
                                           if rk.any() else None)
    return out


def _gamma(env, cfg, data_env_dir, slug: str, out_dir: Path) -> dict:
    """gamma_nt on the evaluation geometry: from the dataset metadata, else estimated."""
    if data_env_dir is not None:
        for meta in sorted(Path(data_env_dir).glob("D*/meta.json")):
            try:
                g = json.loads(meta.read_text()).get("gamma_nt_eval") or {}
            except (OSError, json.JSONDecodeError):
                continue
            if g.get("gamma") is not None:
                return {"gamma": g["gamma"], "ci95": g.get("ci95"), "queries": g.get("queries"),
                        "source": str(meta)}
    f = Path(out_dir) / "gamma.json"
    if f.is_file():
        try:
            return json.loads(f.read_text())
        except (OSError, json.JSONDecodeError):
            pass
    key = jax.random.fold_in(jax.random.fold_in(jax.random.key(cfg.seed), EVAL_TAG + 1), _tag(slug))
    e = env.gamma_nt(key, cfg.eval.gamma_queries, padding=0.0)
    g = {"gamma": float(e.gamma), "ci95": [float(x) for x in e.ci95], "queries": int(e.queries),
         "source": "eval"}
    artifacts.write_text(f, json.dumps(g))
    return g


# ---------------------------------------------------------------------------
# One environment
# ---------------------------------------------------------------------------

def evaluate_env(env, ensemble, cfg, run_dir, *, env_name: str, data_env_dir=None,
                 planner: Callable | None = None, members: Sequence[int] | None = None,
                 log: Callable[[str], None] = print) -> list[dict]:
    """Evaluates every member of ``ensemble`` on one environment (see the module docstring).

    Args:
        env: the :class:`ntq_jax.Env`.
        ensemble: an :class:`ntq_jax.models.Ensemble`, or a list of ``pnet``
            callables (one per model; e.g. stand-ins in tests).
        cfg: the resolved :class:`ntq_jax.config.Config`.
        run_dir: the run folder (``eval/`` and ``paths/`` are written there).
        env_name: the name in ``cfg.envs``.
        data_env_dir: the environment's dataset folder (for gamma_nt and the
            datasets' p_nt); optional.
        planner: a reference planner callable ``(env, q, *, padding, seed)`` instead
            of ``cfg.planner.name``.
        members: which members to evaluate (default all).
        log: progress messages.

    Returns:
        One result row (dict) per (model, query kind, steerTo).
    """
    slug = env_slug(env_name)
    run_dir = Path(run_dir)
    out_dir = run_dir / "eval" / slug
    pnets = member_pnets(ensemble) if hasattr(ensemble, "params") else list(ensemble)
    members = list(range(len(pnets))) if members is None else list(members)
    queries = test_queries(env, cfg, slug, out_dir)
    ref = reference_plans(env, cfg, env_name, slug, queries, out_dir, planner)
    gamma = _gamma(env, cfg, data_env_dir, slug, out_dir)
    specs = [dict(p_nt=d.p_nt, prune=d.prune) for d in cfg.data.datasets]
    rows = []
    for steer in cfg.eval.steer:
        opts = NP.PlannerOptions.from_config(cfg.eval, steer=steer)
        for m in members:
            for ki, kind in enumerate(KINDS):
                q = queries[kind]
                f = paths_file(run_dir, slug, m, kind, steer)
                fp = _fp(cfg.hash(), slug, m, kind, steer, str(ref["fingerprint"]),
                         NP.ALGORITHM_VERSION)
                got = load_npz(f, fp)
                if got is None:
                    key = jax.random.fold_in(jax.random.fold_in(
                        jax.random.key(cfg.seed), EVAL_TAG + 2), _tag(f"{slug}/{m}/{kind}/{steer}"))
                    res = NP.plan_batch(env, pnets[m], q, key, opts, chunk=cfg.eval.chunk)
                    got = dict(fingerprint=fp, queries=q, paths=res.paths, lengths=res.lengths,
                               success=res.success, costs=res.costs, cause=res.cause,
                               pnet_calls=res.pnet_calls, replans=res.replans,
                               ref_costs=ref[f"{kind}_costs"], ref_status=ref[f"{kind}_status"],
                               seconds=res.seconds, compile_seconds=res.compile_seconds)
                    if f"{kind}_opt_costs" in ref:
                        got["opt_costs"] = ref[f"{kind}_opt_costs"]
                    artifacts.save_npz(f, **got)
                    log(f"  {slug} {model_name(m)} {kind:10s} steer={steer!s:5s}: success "
                        f"{res.success.mean():.3f}, {res.seconds / max(len(q), 1) * 1e3:.2f} "
                        f"ms/query (+{res.compile_seconds:.1f} s compile)")
                row = {
                    "task": cfg.task, "env": env_name, "env_slug": slug, "model": model_name(m),
                    "member": m, "dataset": specs[m] if m < len(specs) else None,
                    "query_kind": kind, "steer": bool(steer),
                    "gamma_nt": gamma.get("gamma"), "gamma_nt_ci95": gamma.get("ci95"),
                    "reference_planner": str(ref["planner"]),
                    "seconds_per_query": float(got["seconds"]) / max(len(q), 1),
                    "compile_seconds": float(got["compile_seconds"]),
                    "reference_seconds_per_query": float(ref[f"{kind}_seconds"]) / max(len(q), 1),
                    "paths_file": str(f.relative_to(run_dir)),
                }
                row.update(metrics(got["success"], got["costs"], got["cause"], got["ref_costs"],
                                   got["ref_status"], got.get("opt_costs")))
                rows.append(row)
    return rows


def recheck_paths(env, npz_path) -> np.ndarray:
    """Independent re-check of a saved paths file: success rows collision-free at padding 0.

    Returns ``(K,)`` bool: for every success, every segment passes ``env.steer_to``
    at padding 0 and the path joins the query's start to its goal (or ends within
    the file's ``delta`` for the variant without steerTo); True for non-successes.
    """
    z = load_npz(npz_path)
    ok = np.ones(len(z["success"]), bool)
    for i in np.flatnonzero(z["success"]):
        p = z["paths"][i, : z["lengths"][i]]
        free = np.asarray(env.steer_to(p[:-1], p[1:], padding=0.0))
        ok[i] = bool(free.all()) and np.allclose(p[0], z["queries"][i, 0], atol=1e-5)
    return ok
