"""Dataset generation (Alg. 2 and Alg. 4 of the paper) and the on-disk dataset format.

Usage::

    from ntq_jax import config, data, make_env
    cfg = config.load("configs/point_small.yaml")
    env = make_env("point/0")
    summary = data.generate_datasets(env, cfg, "runs/data", env_name="point/0")
    d0, d1, d2, d3 = data.load_datasets("runs/data/point_0")
    d3.inputs   # (N, 2d) float32 = (current, goal); d3.targets (N, d) = next waypoint

Algorithms
----------
* **includeData (Alg. 4)**, :func:`include_data`: every segment ``i`` of every
  path gives the sample ``((pi_i, pi_end), pi_{i+1})``. The segments of all
  paths are enumerated at once with array indexing (path-major, then along
  the path, i.e. Alg. 4's order); with pruning, ``steer_to(pi_i, pi_end)`` is
  evaluated for all of them with the shared kernel
  (:func:`ntq_jax.robots.batch.steer_to_cm`) in fixed-size chunks (one
  compilation), and a sample is kept only where it fails (the pair is a
  non-trivial query). The last segment of a path (``pi_{L-1} -> pi_end``) is
  always pruned, since consecutive waypoints of a feasible path see each other.
* **Alg. 2** for a dataset ``(p_nt, prune)``: ``K`` queries, each non-trivial
  (Alg. 3) with probability ``p_nt``, else uniform; each is solved by the
  planner; unsolved queries are recorded (``solved = False``) and contribute no
  sample.

Sharing the planning between datasets
-------------------------------------
The four datasets are generated from two *pools* of queries, each planned once:
a pool ``U`` of i.i.d. uniform queries and a pool ``N`` of i.i.d. non-trivial
queries (Alg. 3, each an independent call of the sampler). Dataset ``j`` draws
its mixing bits ``b_t ~ Bernoulli(p_nt)`` (``t = 0..K-1``, key
``fold_in(k_mix, round(1e6 p_nt))``, so datasets with equal ``p_nt`` share
their queries and paths and differ only in pruning); query ``t`` is the next
unused query of ``N`` if ``b_t`` else the next unused query of ``U``. So dataset ``j`` uses the prefixes
``U[:K - sum(b)]`` and ``N[:sum(b)]``, interleaved in the order of its bits.
Because the bits are independent of the pools and the pool entries are i.i.d.,
the query sequence of every dataset has exactly the distribution of Alg. 2
(a sequence of ``K`` independent draws from the ``p_nt`` mixture); only the
datasets' *joint* distribution changes (they share queries). With the paper's
D0..D3 this gives: D0 = ``U[:K]``; D2 = ``N[:K]``; D3 = the same queries and
paths as D2, pruned; D1 = ``~K/2`` queries of each pool. Planning cost: ``2K``
queries instead of ``4K``. ``meta.json`` records each dataset's pool ranges
(``sharing``).

Long runs
---------
The planner runs over the pools in chunks of ``config.data.chunk`` queries;
each chunk's result is written atomically (temporary name, then
``os.replace``) to ``<env_dir>/.work/<fingerprint>/plan_<start>_<stop>.npz``
together with the queries it solved. A rerun of the same command reuses every
completed chunk (even when the chunk size changed), plans only the missing
ranges, then writes the datasets (each ``.npy`` atomically, ``meta.json`` last,
so a folder without ``meta.json`` is incomplete) and removes the work folder.
Query sampling, the mixing bits and (for the deterministic planners ``astar``
and ``visgraph``) the planning depend only on the seed, never on the chunk
size or the worker count, so the arrays are byte-identical. BIT* stops on a
time budget and is not deterministic (its seed, ``(seed * 1000003 + chunk
start) mod (2^31 - 1)`` per chunk, does not make it so); its completed chunks
are still kept, so a resumed BIT* run loses and duplicates nothing either.

On-disk format (DESIGN.md, "Dataset folder")
--------------------------------------------
``<out>/<env_slug>/env.json`` and ``<out>/<env_slug>/D0..D3/`` each with
``meta.json`` and uncompressed ``.npy`` arrays: ``inputs`` float32 ``(N, 2d)``,
``targets`` float32 ``(N, d)``, ``path_index`` int32 ``(N,)`` (row of
``paths``), ``paths`` float32 ``(P, L_max, d)`` NaN-padded (the solved
queries' paths in query order), ``path_lengths`` int32 ``(P,)``, ``queries``
float32 ``(K, 2, d)``, ``query_kind`` int8 ``(K,)`` (0 uniform, 1
non-trivial, 2 = a trivial query the non-trivial sampler returned after
``n_max`` attempts, :data:`ntq_jax.queries.NT_EXHAUSTED`), ``solved`` bool
``(K,)``. ``meta.json`` also holds the statistics and the sha256 of every array.
A PNG figure per environment (``<env_dir>/figure.png``) shows the map, the
start/goal distributions of D0 (uniform) and D2 (non-trivial) and a few paths.
"""

from __future__ import annotations

import functools
import hashlib
import json
import re
import shutil
import time
import warnings
import zlib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, Callable, NamedTuple, Optional

import jax
import jax.numpy as jnp
import numpy as np

from ntq_jax import artifacts, plotting
from ntq_jax import queries as Q
from ntq_jax.envs import Env
from ntq_jax.geometry import KERNEL_COMPILER_OPTIONS
from ntq_jax.robots.batch import steer_to_cm
from ntq_jax.types import PlanStatus

FORMAT = "ntq_jax.dataset"
FORMAT_VERSION = 1
SEG_CHUNK = 8192  # segments per compiled steer_to call in include_data (fixed: one compilation)

# name -> (dtype, ndim)
ARRAY_SPECS: dict[str, tuple[np.dtype, int]] = {
    "inputs": (np.dtype(np.float32), 2),
    "targets": (np.dtype(np.float32), 2),
    "path_index": (np.dtype(np.int32), 1),
    "paths": (np.dtype(np.float32), 3),
    "path_lengths": (np.dtype(np.int32), 1),
    "queries": (np.dtype(np.float32), 3),
    "query_kind": (np.dtype(np.int8), 1),
    "solved": (np.dtype(np.bool_), 1),
}

Progress = Callable[..., Any]


class DatasetError(ValueError):
    """A missing, truncated, corrupt or inconsistent dataset; the message names the file and the fix."""


class Dataset(NamedTuple):
    """One dataset folder (see the module docstring for shapes and dtypes).

    Attributes:
        inputs: ``(N, 2d)`` float32 (current state, goal state).
        targets: ``(N, d)`` float32 next waypoint.
        path_index: ``(N,)`` int32 row of ``paths`` each sample comes from.
        paths: ``(P, L_max, d)`` float32 solved paths, NaN after ``path_lengths``.
        path_lengths: ``(P,)`` int32 waypoints per path.
        queries: ``(K, 2, d)`` float32 start and goal of every query.
        query_kind: ``(K,)`` int8 0 uniform, 1 non-trivial, 2 non-trivial sampler exhausted.
        solved: ``(K,)`` bool the planner solved the query (the ``P`` paths, in order).
        meta: the parsed ``meta.json``.
    """

    inputs: np.ndarray
    targets: np.ndarray
    path_index: np.ndarray
    paths: np.ndarray
    path_lengths: np.ndarray
    queries: np.ndarray
    query_kind: np.ndarray
    solved: np.ndarray
    meta: dict


def env_slug(name: str) -> str:
    """Folder name of an environment: ``'point/0' -> 'point_0'``, ``'maps/a.json' -> 'a'``."""
    s = str(name)
    if s.lower().endswith(".json"):
        s = Path(s).stem
    s = re.sub(r"[^A-Za-z0-9_.-]+", "_", s).strip("_.")
    return s or "env"


def dataset_names(n: int) -> list[str]:
    """``['D0', ..., 'D{n-1}']``."""
    return [f"D{i}" for i in range(n)]


# ---------------------------------------------------------------------------
# includeData (Alg. 4)
# ---------------------------------------------------------------------------

@functools.partial(jax.jit, static_argnames=("robot", "padding"),
                   compiler_options=KERNEL_COMPILER_OPTIONS)
def _steer_chunk(robot, world, a: jax.Array, b: jax.Array, mask: jax.Array, padding: float):
    return steer_to_cm(robot, world, a.T, b.T, padding, mask=mask)


def steer_to_chunked(env, a, b, *, padding: float | None = None,
                     chunk: int = SEG_CHUNK) -> np.ndarray:
    """``env.steer_to`` over any number of pairs in fixed-size compiled chunks.

    Every call uses the same ``(chunk, d)`` shapes (the tail is padded and
    masked), so one compilation serves every batch size.

    Returns:
        ``(n,)`` bool, True where the straight connection is collision-free.
    """
    pad = env.resolve_padding(padding)
    a = np.asarray(a, np.float32).reshape(-1, env.dim)
    b = np.asarray(b, np.float32).reshape(-1, env.dim)
    n = len(a)
    out = np.zeros(n, bool)
    for lo in range(0, n, chunk):
        hi = min(lo + chunk, n)
        pa = np.zeros((chunk, env.dim), np.float32)
        pb = np.zeros((chunk, env.dim), np.float32)
        m = np.zeros(chunk, bool)
        pa[: hi - lo], pb[: hi - lo], m[: hi - lo] = a[lo:hi], b[lo:hi], True
        out[lo:hi] = np.asarray(_steer_chunk(env.robot, env.world, jnp.asarray(pa),
                                             jnp.asarray(pb), jnp.asarray(m), pad))[: hi - lo]
    return out


def include_data(env, paths, lengths, *, prune: bool, padding: float | None = None):
    """Alg. 4 over every segment of every path at once.

    Sample ``((pi_i, pi_end), pi_{i+1})`` for ``i = 0..L_p-2`` of each path ``p``
    (in path order, then along the path). With ``prune``, the sample is dropped
    when ``steer_to(pi_i, pi_end)`` is collision-free at ``padding``.

    Args:
        env: the :class:`ntq_jax.Env`.
        paths: ``(P, L, d)`` waypoints, NaN-padded after ``lengths[p]`` rows.
        lengths: ``(P,)`` waypoints per path (paths with fewer than 2 give no sample).
        prune: Alg. 4's ``pruneData`` flag.
        padding: geometry of the pruning ``steer_to`` (default: the environment's).

    Returns:
        ``(inputs (N, 2d) float32, targets (N, d) float32, path_index (N,) int32)``.
    """
    paths = np.asarray(paths, np.float32)
    lengths = np.asarray(lengths, np.int64).reshape(-1)
    d = env.dim
    if paths.ndim != 3 or paths.shape[2] != d or paths.shape[0] != lengths.shape[0]:
        raise ValueError(f"paths must have shape (P, L, {d}) and lengths (P,), got "
                         f"{paths.shape} and {lengths.shape}")
    P, L = paths.shape[:2]
    if np.any(lengths < 0) or np.any(lengths > L):
        raise ValueError(f"lengths must be in [0, {L}]")
    seg = np.arange(max(L - 1, 0))[None, :] < (lengths - 1)[:, None]
    p_idx, i_idx = np.nonzero(seg)
    cur = paths[p_idx, i_idx]
    nxt = paths[p_idx, i_idx + 1]
    goal = paths[p_idx, lengths[p_idx] - 1] if len(p_idx) else np.zeros((0, d), np.float32)
    if prune and len(p_idx):
        keep = ~steer_to_chunked(env, cur, goal, padding=padding)
        cur, nxt, goal, p_idx = cur[keep], nxt[keep], goal[keep], p_idx[keep]
    inputs = np.concatenate([cur, goal], axis=1).astype(np.float32).reshape(-1, 2 * d)
    return inputs, nxt.astype(np.float32).reshape(-1, d), p_idx.astype(np.int32)


# ---------------------------------------------------------------------------
# Planners
# ---------------------------------------------------------------------------

class PlanOutput(NamedTuple):
    """The fields of a planner result this module uses (the ``ntq_jax.planners`` contract)."""

    paths: np.ndarray     # (K, L, d) float32 NaN-padded
    lengths: np.ndarray   # (K,) int32
    costs: np.ndarray     # (K,) float64
    status: np.ndarray    # (K,) int8, 0 = solved


def _as_plan_output(res, k: int, d: int) -> PlanOutput:
    lengths = getattr(res, "lengths", None)
    if lengths is None:
        lengths = getattr(res, "path_lengths")
    out = PlanOutput(np.asarray(res.paths, np.float32), np.asarray(lengths, np.int32),
                     np.asarray(res.costs, np.float64), np.asarray(res.status, np.int8))
    if out.paths.ndim != 3 or out.paths.shape[0] != k or out.paths.shape[2] != d:
        raise ValueError(f"planner returned paths of shape {out.paths.shape}, expected ({k}, L, {d})")
    return out


_VISGRAPH_CACHE: dict = {}


def _fallback_visgraph(env, queries, *, padding, seed=0, **_):
    from ntq_jax.planners.visgraph import VisGraph

    key = (id(env), float(padding))
    g = _VISGRAPH_CACHE.get(key)
    if g is None or g[0] is not env:
        g = (env, VisGraph.build(env, padding))
        _VISGRAPH_CACHE[key] = g
    return g[1].plan(queries)


def planner_options(config, env_name: str, name: str | None = None) -> dict:
    """The keyword options passed to ``ntq_jax.planners.plan`` for planner ``name``.

    ``name`` defaults to ``config.planner.name``.
    """
    pc = config.planner
    name = name or pc.name
    if name == "astar":
        return {"resolution": pc.resolution}
    if name == "bitstar":
        return {"time_budget": pc.time_budget_for(env_name), "workers": pc.workers}
    return {}


def resolve_planner(planner, options: dict) -> tuple[Callable, str]:
    """A callable ``(env, queries, *, padding, seed) -> result`` and its name.

    Args:
        planner: a name (``astar``, ``visgraph``, ``bitstar``; solved through
            ``ntq_jax.planners.plan``) or a callable with that signature (e.g. a
            test's fake planner). A callable may set ``deterministic = False``.
        options: extra keyword options for a named planner.
    """
    if callable(planner):
        return planner, getattr(planner, "__name__", "custom")
    name = str(planner)
    try:
        from ntq_jax.planners import plan as _plan  # type: ignore[attr-defined]
    except ImportError:
        _plan = None
    if _plan is not None:
        def run(env, queries, *, padding, seed=0):
            return _plan(env, queries, planner=name, padding=padding, seed=seed, **options)
        return run, name
    if name == "visgraph":
        return _fallback_visgraph, name
    if name == "bitstar":
        from ntq_jax.planners.ompl_bridge import plan_bitstar

        def run_b(env, queries, *, padding, seed=0):
            return plan_bitstar(env, queries, padding=padding, seed=seed, **options)
        return run_b, name
    raise ValueError(f"planner {name!r} is not available: ntq_jax.planners.plan is missing "
                     "(use planner='visgraph' or pass a callable)")


# ---------------------------------------------------------------------------
# Atomic writes
# ---------------------------------------------------------------------------

def _json_default(o):
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def _dumps(obj) -> bytes:
    return (json.dumps(obj, indent=1, sort_keys=True, default=_json_default) + "\n").encode()


# ---------------------------------------------------------------------------
# Progress
# ---------------------------------------------------------------------------

class _NoBar:
    def __init__(self, *a, **k):
        pass

    def update(self, n=1):
        pass

    def set_postfix_str(self, s):
        pass

    def close(self):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *a):
        pass


def _bar(progress, desc: str, total: int | None, unit: str):
    if not progress:
        return _NoBar()
    try:
        from tqdm.auto import tqdm
    except ImportError:  # pragma: no cover
        return _NoBar()
    return tqdm(total=total, desc=desc, unit=unit, leave=True, dynamic_ncols=True)


# ---------------------------------------------------------------------------
# Generation (Alg. 2)
# ---------------------------------------------------------------------------

def _env_key(seed: int, slug: str) -> jax.Array:
    return jax.random.fold_in(jax.random.PRNGKey(seed), zlib.crc32(slug.encode()) & 0x7FFFFFFF)


def mixing_bits(key: jax.Array, k: int, p_nt: float) -> np.ndarray:
    """Alg. 2's draws ``u_rand < p_nt`` for ``k`` queries, ``(k,)`` bool (True = non-trivial).

    The uniforms come from ``fold_in(key, round(1e6 p_nt))``: datasets with the same
    ``p_nt`` get the same bits, hence the same queries (e.g. D3 = D2 pruned).
    """
    if p_nt <= 0.0:
        return np.zeros(k, bool)
    if p_nt >= 1.0:
        return np.ones(k, bool)
    sub = jax.random.fold_in(key, int(round(p_nt * 1_000_000)))
    return np.asarray(jax.random.uniform(sub, (k,))) < p_nt


def _plan_pool(env, pool: np.ndarray, plan_fn, pad: float, seed: int, chunk: int, work: Path,
               progress, desc: str) -> tuple[PlanOutput, int]:
    """Plans ``pool`` in chunks, reusing completed chunk files in ``work``; returns (result, reused)."""
    n, d = len(pool), env.dim
    done: dict[int, tuple[int, Path]] = {}
    for p in work.glob("plan_*_*.npz"):
        m = re.fullmatch(r"plan_(\d+)_(\d+)\.npz", p.name)
        if m:
            lo, hi = int(m.group(1)), int(m.group(2))
            if 0 <= lo < hi <= n and (lo not in done or done[lo][0] < hi):
                done[lo] = (hi, p)
    parts: list[tuple[int, int, Optional[Path]]] = []
    i = 0
    starts = sorted(done)
    while i < n:
        if i in done:
            hi, p = done[i]
            parts.append((i, hi, p))
            i = hi
            continue
        nxt = min([s for s in starts if s > i] + [n])
        hi = min(i + chunk, nxt)
        parts.append((i, hi, None))
        i = hi
    results: list[PlanOutput] = []
    reused = 0
    with _bar(progress, desc, n, "query") as bar:
        for lo, hi, p in parts:
            res = None
            if p is not None:
                try:
                    z = np.load(p, allow_pickle=False)
                    if np.array_equal(z["queries"], pool[lo:hi]):
                        res = PlanOutput(z["paths"], z["lengths"], z["costs"], z["status"])
                        reused += hi - lo
                except (OSError, ValueError, KeyError, zlib.error):
                    res = None
                if res is None:  # stale or damaged: plan again
                    p.unlink(missing_ok=True)
            if res is None:
                # distinct seeds per chunk for randomised planners (ignored by astar/visgraph)
                chunk_seed = (int(seed) * 1_000_003 + lo) % (2 ** 31 - 1)
                raw = plan_fn(env, pool[lo:hi], padding=pad, seed=chunk_seed)
                res = _as_plan_output(raw, hi - lo, d)
                artifacts.save_npz(work / f"plan_{lo:09d}_{hi:09d}.npz", queries=pool[lo:hi],
                                 paths=res.paths, lengths=res.lengths, costs=res.costs,
                                 status=res.status)
            results.append(res)
            bar.update(hi - lo)
    L = max([r.paths.shape[1] for r in results] + [2])
    paths = np.full((n, L, d), np.nan, np.float32)
    lengths = np.zeros(n, np.int32)
    costs = np.full(n, np.inf)
    status = np.zeros(n, np.int8)
    for (lo, hi, _), r in zip(parts, results):
        paths[lo:hi, : r.paths.shape[1]] = r.paths
        lengths[lo:hi], costs[lo:hi], status[lo:hi] = r.lengths, r.costs, r.status
    return PlanOutput(paths, lengths, costs, status), reused


def check_paths(env, queries: np.ndarray, res: PlanOutput, pad: float) -> np.ndarray:
    """``(K,)`` bool: solved, starts/ends at the query, finite, every segment collision-free at ``pad``.

    Vectorised over all segments of all paths with the shared ``steer_to`` kernel.
    """
    k, L, d = res.paths.shape
    lengths = res.lengths.astype(np.int64)
    ok = (res.status == PlanStatus.SOLVED) & (lengths >= 2) & (lengths <= L)
    rows = np.arange(k)
    ln = np.clip(lengths, 1, L)
    # endpoints: must be the query's (a planner may round them by ~1e-6: snap, then check)
    tol = 1e-4 * max(1.0, float(np.nanmax(np.abs(queries))) if queries.size else 1.0)
    for col, pos in ((0, np.zeros(k, np.int64)), (1, ln - 1)):
        close = np.all(np.abs(res.paths[rows, pos] - queries[:, col]) <= tol, axis=1)
        ok &= close
        snap = ok & close
        res.paths[rows[snap], pos[snap]] = queries[snap, col]
    inside = np.arange(L)[None, :] < lengths[:, None]
    ok &= np.all(np.isfinite(res.paths) | ~inside[..., None], axis=(1, 2))
    seg = (np.arange(max(L - 1, 0))[None, :] < (lengths - 1)[:, None]) & ok[:, None]
    p_idx, i_idx = np.nonzero(seg)
    if len(p_idx):
        free = steer_to_chunked(env, res.paths[p_idx, i_idx], res.paths[p_idx, i_idx + 1],
                                padding=pad)
        bad = np.zeros(k, bool)
        np.logical_or.at(bad, p_idx[~free], True)
        ok &= ~bad
    return ok


def _fingerprint(env, config, env_name, pad, prune_pad, planner_name, options, n_u, n_nt) -> str:
    blob = json.dumps({
        "format": FORMAT_VERSION, "env": env.to_json(), "env_name": env_name, "seed": config.seed,
        "pad": pad, "prune_pad": prune_pad, "planner": planner_name, "options": options,
        "n_max": config.sampling.n_max, "n_u": n_u, "n_nt": n_nt,
        "k": config.data.k_train_for(env_name),
        "datasets": [[s.p_nt, s.prune] for s in config.data.datasets],
        "gamma_queries": config.data.gamma_queries, "gamma_eval": config.data.gamma_eval,
    }, sort_keys=True, default=_json_default).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


def _wilson(k: int, n: int) -> list[float]:
    return list(Q.wilson_interval(k, n)) if n else [0.0, 1.0]


def _estimate_gamma(env, key, n: int, pad: float, work: Path, tag: str) -> dict:
    f = work / f"gamma_{tag}.json"
    if f.is_file():
        try:
            return json.loads(f.read_text())
        except (OSError, json.JSONDecodeError):
            pass
    try:
        e = env.gamma_nt(key, n, padding=pad)
        out = {"padding": pad, "gamma": e.gamma, "ci95": list(e.ci95), "queries": e.queries}
    except Q.FreeSpaceTooSmall as err:
        out = {"padding": pad, "gamma": None, "ci95": None, "queries": 0, "error": str(err)}
    artifacts.write_bytes(f, _dumps(out))
    return out


def generate_datasets(env, config, out_dir, *, env_name: str | None = None, planner=None,
                      progress=True, figure: bool = True) -> dict:
    """Generates D0..D3 (``config.data.datasets``) for one environment (Alg. 2 + 4).

    Writes ``<out_dir>/<env_slug>/env.json``, ``<out_dir>/<env_slug>/D<i>/`` (see
    the module docstring) and ``<out_dir>/<env_slug>/figure.png``. Resumable:
    rerunning after an interruption reuses the completed planning chunks; a
    complete, matching output is left untouched.

    Args:
        env: the :class:`ntq_jax.Env` (its padding is the data-generation geometry).
        config: a :class:`ntq_jax.config.Config` (``seed``, ``sampling``, ``data``, ``planner``).
        out_dir: the output root.
        env_name: the name listed in ``config.envs`` (for per-env overrides and
            the folder name); default ``env.name``.
        planner: ``None`` (``config.planner.name``), a planner name, or a callable
            ``(env, queries (K, 2, d), *, padding, seed) -> result`` with ``paths``,
            ``lengths`` (or ``path_lengths``), ``costs`` and ``status`` (0 = solved).
        progress: show tqdm progress bars per stage.
        figure: write the PNG figure.

    Returns:
        A summary dict: ``env_dir``, ``datasets`` (name -> statistics), ``timings``
        (seconds per stage), ``reused_queries``, ``skipped`` (already complete).
    """
    t_all = time.perf_counter()
    timings: dict[str, float] = {}
    env_name = env_name or env.name
    slug = env_slug(env_name)
    env_dir = Path(out_dir) / slug
    env_dir.mkdir(parents=True, exist_ok=True)
    dc = config.data
    specs = list(dc.datasets)
    names = dataset_names(len(specs))
    K = dc.k_train_for(env_name)
    pad = env.resolve_padding(None)
    prune_pad = env.resolve_padding(dc.prune_padding)
    if planner is None:
        planner = config.planner.name
    options = planner_options(config, env_name, None if callable(planner) else str(planner))
    plan_fn, planner_name = resolve_planner(planner, options)
    if callable(planner) and not isinstance(planner, str):
        options = dict(getattr(planner, "options", {}) or {})

    key = _env_key(config.seed, slug)
    k_uni, k_nt, k_mix, k_gam = jax.random.split(key, 4)
    bits = [mixing_bits(k_mix, K, s.p_nt) for s in specs]
    n_nt = max(int(b.sum()) for b in bits)
    n_u = max(int((~b).sum()) for b in bits)
    fp = _fingerprint(env, config, env_name, pad, prune_pad, planner_name, options, n_u, n_nt)

    # already complete?
    if _complete(env_dir, names, fp):
        metas = {nm: json.loads((env_dir / nm / "meta.json").read_text()) for nm in names}
        # an interruption after the last meta.json: finish the figure and the clean-up
        if figure and not (env_dir / "figure.png").is_file():
            try:
                plot_environment(env_dir, out=env_dir / "figure.png")
            except Exception as e:  # noqa: BLE001
                warnings.warn(f"{env_name}: figure not written: {e}", RuntimeWarning, stacklevel=2)
        shutil.rmtree(env_dir / ".work", ignore_errors=True)
        return {"env_dir": str(env_dir), "skipped": True, "fingerprint": fp, "timings": {},
                "reused_queries": 0, "datasets": {nm: m["stats"] for nm, m in metas.items()}}

    work = env_dir / ".work" / fp
    work.mkdir(parents=True, exist_ok=True)
    artifacts.clean_tmp(work)
    env.save_json(env_dir / "env.json")

    # 1. query pools
    t0 = time.perf_counter()
    with _bar(progress, f"{slug}: sample queries", n_u + n_nt, "query") as bar:
        U = (Q.sample_uniform_queries(env.robot, env.world, k_uni, n_u, pad) if n_u
             else np.zeros((0, 2, env.dim), np.float32))
        bar.update(n_u)
        if n_nt:
            N, exh = Q.sample_nontrivial_queries(env.robot, env.world, k_nt, n_nt, pad,
                                                 config.sampling.n_max)
        else:
            N, exh = np.zeros((0, 2, env.dim), np.float32), np.zeros(0, bool)
        bar.update(n_nt)
    pool = np.concatenate([U, N]).astype(np.float32)
    pool_kind = np.concatenate([np.full(n_u, Q.UNIFORM, np.int8),
                                np.where(exh, Q.NT_EXHAUSTED, Q.NON_TRIVIAL).astype(np.int8)])
    timings["sample"] = time.perf_counter() - t0

    # gamma_nt: independent of everything else, overlapped with planning
    gamma_seconds = [0.0]

    def _gammas():
        tg = time.perf_counter()
        gd = _estimate_gamma(env, jax.random.fold_in(k_gam, 0), dc.gamma_queries, pad, work,
                             "data")
        ge = (_estimate_gamma(env, jax.random.fold_in(k_gam, 1), dc.gamma_queries, 0.0, work,
                              "eval") if dc.gamma_eval else
              {"padding": 0.0, "gamma": None, "ci95": None, "queries": 0})
        gamma_seconds[0] = time.perf_counter() - tg
        return gd, ge

    gamma_pool = ThreadPoolExecutor(1, thread_name_prefix="ntq_jax-gamma")
    gamma_future = gamma_pool.submit(_gammas)
    try:
        # 2. planning (chunked, resumable)
        t0 = time.perf_counter()
        res, reused = _plan_pool(env, pool, plan_fn, pad, config.seed, dc.chunk, work, progress,
                                 f"{slug}: plan ({planner_name})")
        timings["plan"] = time.perf_counter() - t0

        # 3. independent check of every path, blocked-ness of every query
        t0 = time.perf_counter()
        good = check_paths(env, pool, res, pad)
        rejected = int(((res.status == PlanStatus.SOLVED) & ~good).sum())
        if rejected:
            warnings.warn(f"{env_name}: {rejected} planner path(s) failed the independent check "
                          f"(endpoints or a segment in collision at padding {pad}); they are "
                          "recorded as unsolved", RuntimeWarning, stacklevel=2)
        blocked = ~steer_to_chunked(env, pool[:, 0], pool[:, 1], padding=pad)
        timings["check"] = time.perf_counter() - t0

        # 4. gamma_nt of the map (computed in a background thread while the planner runs)
        t0 = time.perf_counter()
        g_data, g_eval = gamma_future.result()
        timings["gamma"] = gamma_seconds[0]
        timings["gamma_wait"] = time.perf_counter() - t0
        bar = _bar(progress, f"{slug}: gamma_nt", 1, "estimate")
        bar.update(1)
        bar.close()

        # 5. includeData per dataset, write
        t_inc = t_write = 0.0
        summary: dict[str, dict] = {}
        common = {
            "format": FORMAT, "format_version": FORMAT_VERSION, "env": env.name,
            "env_name": env_name, "env_slug": slug, "seed": config.seed, "k_train": K,
            "padding": pad, "prune_padding": prune_pad,
            "planner": {"name": planner_name, "options": options},
            "sampling": {"n_max": config.sampling.n_max},
            "gamma_nt": g_data, "gamma_nt_eval": g_eval,
            "package_version": _package_version(), "config_hash": config.hash(), "fingerprint": fp,
            "query_kind_values": {"0": "uniform", "1": "non-trivial",
                                  "2": "non-trivial sampler exhausted (trivial)"},
        }
        with _bar(progress, f"{slug}: includeData + write", len(specs), "dataset") as bar:
            for j, (nm, spec, b) in enumerate(zip(names, specs, bits)):
                t0 = time.perf_counter()
                # query t: next of N if b[t] else next of U (pool index n_u + rank in N)
                rank_nt = np.cumsum(b) - 1
                rank_u = np.cumsum(~b) - 1
                idx = np.where(b, n_u + rank_nt, rank_u)
                q, kind = pool[idx], pool_kind[idx]
                solved = good[idx]
                sel = idx[solved]
                lens = res.lengths[sel].astype(np.int32)
                lmax = int(lens.max()) if len(lens) else 0
                paths = np.ascontiguousarray(res.paths[sel, :lmax]) if len(sel) else \
                    np.zeros((0, 0, env.dim), np.float32)
                inputs, targets, pidx = include_data(env, paths, lens, prune=spec.prune,
                                                     padding=prune_pad)
                segments = int(np.maximum(lens - 1, 0).sum())
                t_inc += time.perf_counter() - t0
                t0 = time.perf_counter()
                warn = []
                if len(inputs) == 0:
                    msg = (f"{env_name} {nm}: the dataset has no samples "
                           + ("(pruning removed every segment: no waypoint of any path is blocked "
                              "from its goal, e.g. a map without obstacles)" if spec.prune and segments
                              else "(no query was solved)" if not len(sel) else "(empty)")
                           + "; an empty, valid dataset was written")
                    warn.append(msg)
                    warnings.warn(msg, RuntimeWarning, stacklevel=2)
                n_exh = int((kind == Q.NT_EXHAUSTED).sum())
                if n_exh:
                    msg = (f"{env_name} {nm}: {n_exh} non-trivial draw(s) found no blocked query in "
                           f"n_max={config.sampling.n_max} attempts and are trivial (query_kind 2)")
                    warn.append(msg)
                nblk = int(blocked[idx].sum())
                stats = {
                    "queries": K, "uniform": int((kind == Q.UNIFORM).sum()),
                    "non_trivial": int((kind == Q.NON_TRIVIAL).sum()), "nt_exhausted": n_exh,
                    "solved": int(solved.sum()), "unsolved": int(K - solved.sum()),
                    "rejected_paths": int(((res.status[idx] == PlanStatus.SOLVED) & ~solved).sum()),
                    "paths": int(len(sel)), "segments": segments, "samples": int(len(inputs)),
                    "pruned": segments - int(len(inputs)) if spec.prune else 0,
                    "fraction_pruned": ((segments - len(inputs)) / segments
                                        if spec.prune and segments else 0.0),
                    "mean_waypoints": float(lens.mean()) if len(lens) else 0.0,
                    "max_waypoints": lmax,
                    "blocked_fraction": nblk / K, "blocked_fraction_ci95": _wilson(nblk, K),
                    "mean_cost": float(res.costs[sel].mean()) if len(sel) else None,
                    "gamma_nt": g_data["gamma"], "gamma_nt_eval": g_eval["gamma"],
                }
                arrays = {"inputs": inputs, "targets": targets, "path_index": pidx,
                          "paths": paths.astype(np.float32), "path_lengths": lens,
                          "queries": q.astype(np.float32), "query_kind": kind.astype(np.int8),
                          "solved": solved.astype(np.bool_)}
                sharing = {"uniform_pool": [0, int((~b).sum())],
                           "nontrivial_pool": [0, int(b.sum())],
                           "same_queries_as": [names[i] for i in range(j)
                                               if np.array_equal(bits[i], b)]}
                meta = dict(common, name=nm, p_nt=spec.p_nt, prune=spec.prune, stats=stats,
                            sharing=sharing, warnings=warn)
                _write_dataset(env_dir / nm, arrays, meta)
                summary[nm] = stats
                t_write += time.perf_counter() - t0
                bar.update(1)
        timings["include"] = t_inc
        timings["write"] = t_write

        if figure:
            t0 = time.perf_counter()
            try:
                plot_environment(env_dir, out=env_dir / "figure.png")
            except Exception as e:  # a figure must never cost the data  # noqa: BLE001
                warnings.warn(f"{env_name}: figure not written: {e}", RuntimeWarning, stacklevel=2)
            timings["figure"] = time.perf_counter() - t0

        # the datasets are complete: drop this run's chunks and any stale ones of older settings
        shutil.rmtree(env_dir / ".work", ignore_errors=True)
        timings["total"] = time.perf_counter() - t_all
        return {"env_dir": str(env_dir), "skipped": False, "fingerprint": fp, "timings": timings,
                "reused_queries": reused, "datasets": summary, "planned_queries": len(pool)}

    finally:
        gamma_pool.shutdown(wait=True)

def _package_version() -> str:
    try:
        from ntq_jax import __version__
        return __version__
    except ImportError:  # pragma: no cover
        return "unknown"


def _complete(env_dir: Path, names: list[str], fp: str) -> bool:
    for nm in names:
        m = env_dir / nm / "meta.json"
        try:
            meta = json.loads(m.read_text())
        except (OSError, json.JSONDecodeError):
            return False
        if meta.get("fingerprint") != fp:
            return False
        for a in ARRAY_SPECS:
            if not (env_dir / nm / f"{a}.npy").is_file():
                return False
    return True


def _write_dataset(folder: Path, arrays: dict[str, np.ndarray], meta: dict):
    """Writes one dataset folder: ``meta.json`` removed first, arrays atomically, ``meta.json`` last."""
    folder.mkdir(parents=True, exist_ok=True)
    artifacts.clean_tmp(folder)
    (folder / "meta.json").unlink(missing_ok=True)
    info = {}
    for name, (dtype, ndim) in ARRAY_SPECS.items():
        arr = np.asarray(arrays[name])
        assert arr.dtype == dtype and arr.ndim == ndim, (name, arr.dtype, arr.shape)
        digest = artifacts.sha256(artifacts.save_npy(folder / f"{name}.npy", arr))
        info[name] = {"dtype": dtype.str, "shape": list(arr.shape), "sha256": digest}
    artifacts.write_bytes(folder / "meta.json", _dumps(dict(meta, arrays=info)))


# ---------------------------------------------------------------------------
# Loading
# ---------------------------------------------------------------------------

_FIX = "regenerate it with scripts/generate_data.py (the same command resumes or rewrites it)"


def load_dataset(folder, mmap: bool = True, verify: bool = True) -> Dataset:
    """Loads and validates one dataset folder.

    Args:
        folder: a ``D<i>`` folder.
        mmap: memory-map the arrays (``mmap_mode="r"``).
        verify: check each file's sha256 against ``meta.json`` (detects corruption).

    Raises:
        DatasetError: missing/unparsable ``meta.json`` (an incomplete dataset),
            a missing, truncated or corrupt array, or shapes/dtypes inconsistent
            with each other or with the metadata; the message names the file and the fix.
    """
    folder = Path(folder)
    mpath = folder / "meta.json"
    if not folder.is_dir():
        raise DatasetError(f"{folder}: no such dataset folder; {_FIX}")
    if not mpath.is_file():
        raise DatasetError(f"{mpath}: missing, the dataset is incomplete (generation interrupted?); "
                           f"{_FIX}")
    try:
        meta = json.loads(mpath.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise DatasetError(f"{mpath}: not valid JSON ({e}); {_FIX}") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise DatasetError(f"{mpath}: not an ntq_jax dataset (format {meta.get('format')!r} "
                           if isinstance(meta, dict) else f"{mpath}: not an ntq_jax dataset (")
    if meta.get("format_version") != FORMAT_VERSION:
        raise DatasetError(f"{mpath}: format version {meta.get('format_version')!r}, this "
                           f"ntq_jax reads {FORMAT_VERSION}; {_FIX}")
    info = meta.get("arrays") or {}
    arrs = {}
    for name, (dtype, ndim) in ARRAY_SPECS.items():
        f = folder / f"{name}.npy"
        if not f.is_file():
            raise DatasetError(f"{f}: missing; {_FIX}")
        want = info.get(name)
        if not isinstance(want, dict):
            raise DatasetError(f"{mpath}: no entry for array {name!r}; {_FIX}")
        if verify and artifacts.sha256(f) != want.get("sha256"):
            raise DatasetError(f"{f}: corrupt (sha256 differs from meta.json); {_FIX}")
        try:
            if mmap and f.stat().st_size > 0:
                try:
                    a = np.load(f, mmap_mode="r", allow_pickle=False)
                except ValueError:
                    a = np.load(f, allow_pickle=False)  # e.g. zero-size arrays cannot be mapped
            else:
                a = np.load(f, allow_pickle=False)
        except (OSError, ValueError, EOFError) as e:
            raise DatasetError(f"{f}: truncated or corrupt ({e}); {_FIX}") from None
        if a.dtype != dtype or a.ndim != ndim:
            raise DatasetError(f"{f}: dtype {a.dtype} shape {a.shape}, expected {dtype} with "
                               f"{ndim} dimensions; {_FIX}")
        if list(a.shape) != list(want.get("shape", [])):
            raise DatasetError(f"{f}: shape {a.shape} differs from meta.json {want.get('shape')}; "
                               f"{_FIX}")
        arrs[name] = a
    _check_consistency(folder, arrs, meta)
    return Dataset(meta=meta, **arrs)


def _check_consistency(folder: Path, a: dict, meta: dict):
    def bad(msg):
        raise DatasetError(f"{folder}: {msg}; {_FIX}")

    K, two, d = a["queries"].shape
    if two != 2:
        bad(f"queries.npy has shape {a['queries'].shape}, expected (K, 2, d)")
    N = a["inputs"].shape[0]
    P = a["paths"].shape[0]
    if a["inputs"].shape[1] != 2 * d:
        bad(f"inputs.npy has {a['inputs'].shape[1]} columns, expected 2d = {2 * d}")
    if a["targets"].shape != (N, d):
        bad(f"targets.npy shape {a['targets'].shape}, expected ({N}, {d})")
    if a["path_index"].shape != (N,):
        bad(f"path_index.npy shape {a['path_index'].shape}, expected ({N},)")
    if a["query_kind"].shape != (K,) or a["solved"].shape != (K,):
        bad(f"query_kind/solved must have shape ({K},)")
    if a["path_lengths"].shape != (P,):
        bad(f"path_lengths.npy shape {a['path_lengths'].shape}, expected ({P},)")
    if P and a["paths"].shape[2] != d:
        bad(f"paths.npy shape {a['paths'].shape}, expected (P, L, {d})")
    if int(np.count_nonzero(a["solved"])) != P:
        bad(f"{int(np.count_nonzero(a['solved']))} solved queries but {P} paths")
    if N and (int(a["path_index"].min()) < 0 or int(a["path_index"].max()) >= P):
        bad("path_index.npy points outside paths.npy")
    if P and (int(a["path_lengths"].min()) < 2 or int(a["path_lengths"].max()) > a["paths"].shape[1]):
        bad("path_lengths.npy out of range [2, L_max]")
    kinds = np.unique(np.asarray(a["query_kind"]))
    if np.any((kinds < 0) | (kinds > 2)):
        bad(f"query_kind.npy holds values {kinds.tolist()}, expected 0, 1 or 2")
    st = meta.get("stats", {})
    if st.get("samples") is not None and st["samples"] != N:
        bad(f"meta.json says {st['samples']} samples, inputs.npy holds {N}")
    if st.get("queries") is not None and st["queries"] != K:
        bad(f"meta.json says {st['queries']} queries, queries.npy holds {K}")


def load_datasets(env_dir, mmap: bool = True, verify: bool = True) -> list[Dataset]:
    """Loads ``D0, D1, ...`` of one environment folder (all ``D<i>`` present, in order).

    Raises:
        DatasetError: no dataset folder, a gap in the numbering, or any dataset invalid.
    """
    env_dir = Path(env_dir)
    found = sorted((int(p.name[1:]), p) for p in env_dir.glob("D*")
                   if p.is_dir() and re.fullmatch(r"D\d+", p.name))
    if not found:
        raise DatasetError(f"{env_dir}: no D0..D3 dataset folders; generate them with "
                           "scripts/generate_data.py")
    if [i for i, _ in found] != list(range(len(found))):
        raise DatasetError(f"{env_dir}: dataset folders {[p.name for _, p in found]} are not "
                           f"D0..D{len(found) - 1}; {_FIX}")
    return [load_dataset(p, mmap=mmap, verify=verify) for _, p in found]


# ---------------------------------------------------------------------------
# Synthetic rows
# ---------------------------------------------------------------------------

def straight_line_rows(seed: int, lo, hi, *, step: float, n_paths: int | None = None,
                       n_rows: int | None = None):
    """Synthetic MPNet rows without obstacles or a planner (smoke tests, benchmarks).

    Straight paths between uniform random points of the box ``[lo, hi]``, cut
    into ``ceil(length / step)`` equal steps; each step is a row ``(current, goal)
    -> next``. Give ``n_paths`` (all rows of that many paths) or ``n_rows`` (the
    first ``n_rows`` rows of as many paths as needed).

    Returns:
        ``(inputs (N, 2 d) float32, targets (N, d) float32, path_index (N,) int32)``.
    """
    if (n_paths is None) == (n_rows is None):
        raise ValueError("straight_line_rows: give exactly one of n_paths and n_rows")
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(lo), np.asarray(hi)
    xs, ys, pis, p = [], [], [], 0
    while (p < n_paths) if n_rows is None else (len(xs) < n_rows):
        a, b = rng.uniform(lo, hi), rng.uniform(lo, hi)
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / step)))
        pts = a + (b - a) * (np.arange(n + 1) / n)[:, None]
        for k in range(n):
            xs.append(np.concatenate([pts[k], b]))
            ys.append(pts[k + 1])
            pis.append(p)
        p += 1
    end = len(xs) if n_rows is None else n_rows
    return (np.array(xs[:end], np.float32), np.array(ys[:end], np.float32),
            np.array(pis[:end], np.int32))


def plot_environment(env_dir, out=None, n_points: int = 400, n_paths: int = 6) -> Path:
    """:func:`ntq_jax.plotting.dataset_figure` of a dataset folder (default ``<env_dir>/figure.png``)."""
    env_dir = Path(env_dir)
    env = Env.from_json(json.loads((env_dir / "env.json").read_text()))
    out = Path(out) if out is not None else env_dir / "figure.png"
    return plotting.dataset_figure(env, load_datasets(env_dir, verify=False), out,
                                   n_points=n_points, n_paths=n_paths)


__all__ = ["Dataset", "DatasetError", "include_data", "generate_datasets", "load_dataset",
           "load_datasets", "env_slug", "plot_environment", "steer_to_chunked", "check_paths",
           "mixing_bits", "resolve_planner", "planner_options", "straight_line_rows",
           "ARRAY_SPECS"]
