"""Evaluation of a trained PNet ensemble with the neural planner (Section V of the paper).

For every environment: ``K_test`` fresh uniform and ``K_test`` fresh non-trivial
test queries (keys derived from the run seed with a tag no other stage uses, so
they are disjoint from the training queries), solved by the classical reference
planner (the task's planner on the evaluation geometry, padding 0, at the
evaluation budget) and, for point robots, by the exact visibility graph (both in
:mod:`ntq_jax.experiment.references`); then by the neural planner
(:mod:`ntq_jax.neural`) with every ensemble member,
with and/or without steerTo (``config.eval.steer``), and (``config.eval.ensemble``,
with at least two members, when every member is evaluated) rows of the
members together, measured the same way on the same queries:

* ``PNet_ens``: the ensemble neural planner (every member proposes each next
  state, a fixed rule picks one: :func:`ntq_jax.neural.proposals.choose`), planned
  with its own key;
* ``PNet_best-of-<N>``: per query the cheapest successful path of the N members'
  own plans (:func:`best_of`), from their saved paths files without replanning;
* ``PNet_cascade``: the members as fallbacks
  (:func:`ntq_jax.neural.driver.plan_cascade`), in the order of their success
  on validation queries (:func:`validation_order`): best-of-N's successes at
  about one member's work plus the fallbacks' on the failures.

Metrics per (environment, model, test query kind, steerTo):

* success ratio ``k / K_test`` with its 95% Wilson interval (a success is a path
  that reaches the goal and is collision-free on the evaluation geometry);
* cost ratio = neural cost / reference cost per query, averaged over the
  queries both solved (and the same against the visibility-graph optimum for
  point robots);
* planning time per query (batched wall time / K_test, compile time apart);
* failures by cause (:data:`ntq_jax.types.CAUSE_NAMES`): ``no_path``,
  ``infeasible``, ``invalid_query``, and ``reference_failed`` (queries the
  reference planner did not solve);
* the success ratio of the in-band and of the out-of-band test queries apart
  (:func:`band_metrics`): test queries are sampled at ``eval.query_padding``
  (default 0, the evaluation geometry) while the training data lives at the
  environment's padding, so a query is "in band" when both its endpoints are
  valid at the environment's padding (states like those training saw) and "out
  of band" when one lies inside the padding band.

Files (written atomically; a complete file made from the same inputs, as its
fingerprint says, is reused on a rerun)::

    <run>/eval/<env_slug>/queries.npz          test queries (uniform, nontrivial)
    <run>/eval/<env_slug>/reference.npz        reference (and optimum) paths and costs
    <run>/paths/<env_slug>/<model>_<uniform|nontrivial>[_nosteer].npz
        queries, paths (NaN padded), lengths, success, costs, cause, ref_costs,
        opt_costs, pnet_calls, replans, seconds, compile_seconds, fingerprint
        (best-of-N and the cascade also: member, the index of the member whose
        path is kept; the cascade: order, its member order)
    <run>/paths/<env_slug>/validation[_nosteer].npz   the cascade's member order

``<model>`` is ``PNet_0`` .. ``PNet_<M-1>``, ``PNet_ens``, ``PNet_best-of-<M>`` and
``PNet_cascade``.

Measured evaluation times: BENCHMARKS.md, "Neural planner evaluation".
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Callable, Sequence

import jax
import numpy as np

from ntq_jax import artifacts
from ntq_jax import neural as NP
from ntq_jax.envs import env_slug
from ntq_jax.experiment import config as C
from ntq_jax.experiment.metrics import band_metrics, best_of, in_band, metrics
from ntq_jax.experiment.references import (
    EVAL_TAG,
    _tag,
    reference_plans,
    reuse_roadmaps,
    test_queries,
)
from ntq_jax.models import member_pnets
from ntq_jax.neural.options import ALGORITHM_VERSION
from ntq_jax.types import QUERY_KINDS, TASK_OF_ROBOT

ENSEMBLE = "ens"  # model id of the ensemble neural planner (row PNet_ens)
CASCADE = "cascade"  # model id of the members as fallbacks (row PNet_cascade)
VALIDATION_TAG = EVAL_TAG + 5  # key tag of the cascade's validation queries
CASCADE_VERSION = 4  # in the cascade cells' fingerprint: bump when plan_cascade's results change


def task_of(env) -> str:
    """The task of an environment's robot (``point``, ``rigid`` or ``nlink``): the paper
    table its rows belong to, whatever ``config.task`` says (a config may mix robots)."""
    return TASK_OF_ROBOT.get(env.robot.kind, env.robot.kind)


def best_id(num_members: int) -> str:
    """Model id of the best-of-N row (``best-of-4`` for four members)."""
    return f"best-of-{num_members}"


def model_name(member: int | str) -> str:
    """``PNet_<m>`` for member ``m``; ``PNet_ens``, ``PNet_best-of-<N>`` and ``PNet_cascade``
    for the ensemble rows."""
    return f"PNet_{member}"


def paths_file(run_dir, slug: str, member: int | str, kind: str, steer: bool) -> Path:
    """``<run>/paths/<slug>/PNet_<m>_<kind>[_nosteer].npz`` (``m``: a member index,
    :data:`ENSEMBLE` or :func:`best_id`)."""
    return (
        Path(run_dir)
        / "paths"
        / slug
        / f"{model_name(member)}_{kind}{'' if steer else '_nosteer'}.npz"
    )


# ---------------------------------------------------------------------------
# One environment
# ---------------------------------------------------------------------------


def _data_planner(cfg, env_name: str, data_env_dir) -> str:
    """The planner that made the datasets (their metadata), else the config's for the map."""
    for meta in sorted(Path(data_env_dir).glob("D*/meta.json")) if data_env_dir else []:
        try:
            return str(json.loads(meta.read_text())["planner"]["name"])
        except (OSError, KeyError, TypeError, json.JSONDecodeError):
            continue
    return cfg.planner.name_for(env_name)


def _gamma(env, cfg, data_env_dir, slug: str, out_dir: Path) -> dict:
    """gamma_nt on the evaluation geometry: from the dataset metadata, else estimated."""
    if data_env_dir is not None:
        for meta in sorted(Path(data_env_dir).glob("D*/meta.json")):
            try:
                g = json.loads(meta.read_text()).get("gamma_nt_eval") or {}
            except (OSError, json.JSONDecodeError):
                continue
            if g.get("gamma") is not None:
                return {
                    "gamma": g["gamma"],
                    "ci95": g.get("ci95"),
                    "queries": g.get("queries"),
                    "source": str(meta),
                }
    f = Path(out_dir) / "gamma.json"
    if f.is_file():
        try:
            return json.loads(f.read_text())
        except (OSError, json.JSONDecodeError):
            pass
    key = jax.random.fold_in(jax.random.fold_in(jax.random.key(cfg.seed), EVAL_TAG + 1), _tag(slug))
    e = env.gamma_nt(key, cfg.eval.gamma_queries, padding=0.0)
    g = {
        "gamma": float(e.gamma),
        "ci95": [float(x) for x in e.ci95],
        "queries": int(e.queries),
        "source": "eval",
    }
    artifacts.write_json(f, g, indent=None)
    return g


@dataclasses.dataclass(frozen=True)
class _EnvEval:
    """What every (model, query kind, steerTo) cell of one environment shares."""

    env: object
    cfg: object
    run_dir: Path
    env_name: str
    slug: str
    queries: dict
    ref: dict
    gamma: dict
    data_planner: str
    in_band: dict  # {query kind: (K,) bool}, see in_band()
    log: Callable[[str], None]


def _plan_cell(ctx: _EnvEval, pnet, m: int | str, kind: str, steer, order=None) -> dict:
    """Neural plans of one cell, as saved in its paths file (``order``: the cascade's)."""
    cfg, q = ctx.cfg, ctx.queries[kind]
    key = jax.random.fold_in(
        jax.random.fold_in(jax.random.key(cfg.seed), EVAL_TAG + 2),
        _tag(f"{ctx.slug}/{m}/{kind}/{steer}"),
    )
    opts = C.neural_options(cfg.eval, steer=steer)
    if m == CASCADE:
        res = NP.plan_cascade(ctx.env, pnet, q, key, opts, order=order, chunk=cfg.eval.chunk)
    else:
        res = NP.plan_batch(ctx.env, pnet, q, key, opts, chunk=cfg.eval.chunk)
    out = dict(
        queries=q,
        paths=res.paths,
        lengths=res.lengths,
        success=res.success,
        costs=res.costs,
        cause=res.cause,
        pnet_calls=res.pnet_calls,
        replans=res.replans,
        ref_costs=ctx.ref[f"{kind}_costs"],
        ref_status=ctx.ref[f"{kind}_status"],
        seconds=res.seconds,
        compile_seconds=res.compile_seconds,
    )
    if f"{kind}_opt_costs" in ctx.ref:
        out["opt_costs"] = ctx.ref[f"{kind}_opt_costs"]
    if res.member is not None:
        out.update(member=res.member, order=np.asarray(order, np.int8))
    ctx.log(
        f"  {ctx.slug} {model_name(m)} {kind:10s} steer={steer!s:5s}: success "
        f"{res.success.mean():.3f}, {res.seconds / max(len(q), 1) * 1e3:.2f} "
        f"ms/query (+{res.compile_seconds:.1f} s compile)"
    )
    return out


def _cell(
    ctx: _EnvEval, pnet, m: int | str, kind: str, steer, *extra, order=None
) -> tuple[dict, dict]:
    """The result row of one (model, query kind, steerTo) cell, planned or loaded, and
    its paths file's arrays.

    ``m`` is a member index (``pnet`` its PNet), :data:`ENSEMBLE` or
    :data:`CASCADE` (``pnet`` the members' list; ``order`` the cascade's member
    order); ``extra`` is added to the fingerprint.
    """
    cfg = ctx.cfg
    f = paths_file(ctx.run_dir, ctx.slug, m, kind, steer)
    fp = artifacts.fingerprint(
        cfg.hash(),
        ctx.slug,
        m,
        kind,
        steer,
        str(ctx.ref["fingerprint"]),
        ALGORITHM_VERSION,
        *extra,
        *([] if order is None else [list(map(int, order))]),
    )
    got = artifacts.compute_or_load(f, fp, lambda: _plan_cell(ctx, pnet, m, kind, steer, order))
    return _row(ctx, m, kind, steer, f, got), got


def _best_cell(ctx: _EnvEval, members: list[dict], kind: str, steer) -> dict:
    """The best-of-N row from the members' paths files' arrays (saved like a planned cell)."""
    m = best_id(len(members))
    f = paths_file(ctx.run_dir, ctx.slug, m, kind, steer)
    fp = artifacts.fingerprint(
        ctx.cfg.hash(),
        ctx.slug,
        m,
        kind,
        steer,
        str(ctx.ref["fingerprint"]),
        ALGORITHM_VERSION,
        [str(z["fingerprint"]) for z in members],
    )

    def compute():
        out = best_of(members)
        ctx.log(
            f"  {ctx.slug} {model_name(m)} {kind:10s} steer={steer!s:5s}: success "
            f"{out['success'].mean():.3f} (from the members' saved plans)"
        )
        return out

    return _row(ctx, m, kind, steer, f, artifacts.compute_or_load(f, fp, compute))


def validation_order(ctx: _EnvEval, pnets: list, steer) -> list[int]:
    """The cascade's member order: by success on validation queries, best first.

    ``K_test`` fresh non-trivial queries (sampled like the test queries, with a
    key tag of their own, so disjoint from them and from the training queries)
    are planned by every member; members are ordered by their success, ties by
    index. Saved in ``<run>/paths/<env_slug>/validation[_nosteer].npz``
    (``success`` per member, ``order``, ``seconds``), reused on a rerun.
    """
    cfg = ctx.cfg
    f = Path(ctx.run_dir) / "paths" / ctx.slug / f"validation{'' if steer else '_nosteer'}.npz"
    fp = artifacts.fingerprint(
        cfg.hash(), ctx.slug, "validation", steer, len(pnets), ALGORITHM_VERSION
    )

    def compute():
        key = jax.random.fold_in(
            jax.random.fold_in(jax.random.key(cfg.seed), VALIDATION_TAG), _tag(ctx.slug)
        )
        qpad = ctx.env.resolve_padding(cfg.eval.query_padding)
        q, _ = ctx.env.sample_queries(
            jax.random.fold_in(key, 0), cfg.eval.k_test, 1.0, padding=qpad, n_max=cfg.sampling.n_max
        )
        opts = C.neural_options(cfg.eval, steer=steer)
        res = [
            NP.plan_batch(
                ctx.env,
                p,
                np.asarray(q, np.float32),
                jax.random.fold_in(key, 1 + m),
                opts,
                chunk=cfg.eval.chunk,
            )
            for m, p in enumerate(pnets)
        ]
        success = np.array([r.success.mean() for r in res])
        order = np.argsort(-success, kind="stable").astype(np.int8)
        ctx.log(
            f"  {ctx.slug} cascade order {order.tolist()} (validation success "
            f"{np.round(success, 3).tolist()})"
        )
        return dict(success=success, order=order, seconds=sum(r.seconds for r in res))

    return [int(m) for m in artifacts.compute_or_load(f, fp, compute)["order"]]


def _row(ctx: _EnvEval, m: int | str, kind: str, steer, f: Path, got: dict) -> dict:
    """The result row of a cell from its paths file's arrays."""
    cfg, k = ctx.cfg, max(len(ctx.queries[kind]), 1)
    specs = [dict(p_nt=d.p_nt, prune=d.prune) for d in cfg.data.datasets]
    member = m if isinstance(m, int) else None
    row = {
        "task": task_of(ctx.env),
        "env": ctx.env_name,
        "env_slug": ctx.slug,
        "model": model_name(m),
        "member": member,
        "dataset": specs[member] if member is not None and member < len(specs) else None,
        "query_kind": kind,
        "steer": bool(steer),
        "gamma_nt": ctx.gamma.get("gamma"),
        "gamma_nt_ci95": ctx.gamma.get("ci95"),
        "reference_planner": str(ctx.ref["planner"]),
        "data_planner": ctx.data_planner,
        "seconds_per_query": float(got["seconds"]) / k,
        "compile_seconds": float(got["compile_seconds"]),
        "reference_seconds_per_query": float(ctx.ref[f"{kind}_seconds"]) / k,
        "paths_file": str(f.relative_to(ctx.run_dir)),
    }
    row.update(
        metrics(
            got["success"],
            got["costs"],
            got["cause"],
            got["ref_costs"],
            got["ref_status"],
            got.get("opt_costs"),
        )
    )
    row["band_padding"] = float(ctx.env.padding)
    row.update(band_metrics(got["success"], ctx.in_band[kind]))
    return row


def evaluate_env(
    env,
    ensemble,
    cfg,
    run_dir,
    *,
    env_name: str,
    data_env_dir=None,
    planner: Callable | None = None,
    members: Sequence[int] | None = None,
    eval_dir=None,
    log: Callable[[str], None] = print,
    executor=None,
) -> list[dict]:
    """Evaluates every member of ``ensemble`` on one environment (see the module docstring).

    Args:
        env: the :class:`ntq_jax.Env`.
        ensemble: an :class:`ntq_jax.models.Ensemble`, or a list of ``pnet``
            callables (one per model; e.g. stand-ins in tests).
        cfg: the resolved :class:`ntq_jax.experiment.config.Config`.
        run_dir: the run folder (``eval/`` and ``paths/`` are written there).
        env_name: the name in ``cfg.envs``.
        data_env_dir: the environment's dataset folder (for gamma_nt and the
            datasets' p_nt); optional.
        planner: a reference planner callable ``(env, q, *, padding, seed)`` instead
            of the map's planner (``cfg.planner.name_for(env_name)``).
        members: which members to evaluate (default all).
        eval_dir: the folder of ``queries.npz``, ``reference.npz`` and ``gamma.json``
            (default ``<run_dir>/eval/<env_slug>``); several runs can share one, e.g.
            the learning curve's sizes (``ntq_jax.experiment.curve``), which then plan on the
            same test queries and compute the references once.
        log: progress messages.
        executor: where the reference planner's chunks run (:func:`reference_plans`).

    Returns:
        One result row (dict) per (model, query kind, steerTo): per steerTo variant
        the members', then ``PNet_ens``, ``PNet_best-of-<N>`` and ``PNet_cascade`` (as
        ``cfg.eval.ensemble_rows`` asks; only with at least two models and when every
        one of them is evaluated).
    """
    slug = env_slug(env_name, env)
    run_dir = Path(run_dir)
    out_dir = run_dir / "eval" / slug if eval_dir is None else Path(eval_dir)
    if data_env_dir is not None and planner is None:
        reuse_roadmaps(Path(data_env_dir) / "roadmap", out_dir)
    pnets = list(ensemble) if isinstance(ensemble, (list, tuple)) else member_pnets(ensemble)
    members = list(range(len(pnets)) if members is None else members)
    queries = test_queries(env, cfg, slug, out_dir)
    ctx = _EnvEval(
        env,
        cfg,
        run_dir,
        env_name,
        slug,
        queries,
        reference_plans(env, cfg, env_name, slug, queries, out_dir, planner, executor),
        _gamma(env, cfg, data_env_dir, slug, out_dir),
        _data_planner(cfg, env_name, data_env_dir),
        {kind: in_band(env, q) for kind, q in queries.items()},
        log,
    )
    together = (
        len(pnets) >= 2 and sorted(members) == list(range(len(pnets))) and cfg.eval.ensemble_rows
    )
    rows = []
    for steer in cfg.eval.steer:
        saved = {}
        for m in members:
            for kind in QUERY_KINDS:
                row, saved[m, kind] = _cell(ctx, pnets[m], m, kind, steer)
                rows.append(row)
        if together and "ens" in cfg.eval.ensemble_rows:
            rows += [
                _cell(ctx, pnets, ENSEMBLE, kind, steer, len(pnets))[0] for kind in QUERY_KINDS
            ]
        if together and "best" in cfg.eval.ensemble_rows:
            rows += [
                _best_cell(ctx, [saved[m, kind] for m in members], kind, steer)
                for kind in QUERY_KINDS
            ]
        if together and CASCADE in cfg.eval.ensemble_rows:
            order = validation_order(ctx, pnets, steer)
            rows += [
                _cell(ctx, pnets, CASCADE, kind, steer, len(pnets), CASCADE_VERSION, order=order)[0]
                for kind in QUERY_KINDS
            ]
    return rows
