"""Streaming data at scale: queries planned, shortcut and verified chunk by chunk into files.

:func:`stream_chunks` makes ``n_queries`` queries of one environment in chunks of
``chunk`` queries. Chunk ``i`` is self-contained: its queries come from the key
``fold_in(key(seed), i)`` (the first half of the chunk uniform, the second half
non-trivial, Alg. 3), they are planned on the environment's roadmap
(:func:`ntq_jax.planners.roadmap.plan_roadmap`: search, shortcut and the final
verification of every path with the chosen motion check, the certified one by
default), and the chunk is written atomically as ``<out>/chunk_<i:06d>.npz``:

* ``queries (n, 2, d)`` float32 and ``kind (n,)`` int8 (:mod:`ntq_jax.queries`' kinds);
* ``paths (n, L, d)`` float32 NaN-padded, ``lengths (n,)`` int32, ``costs (n,)``
  float64 (inf where not solved), ``status (n,)`` :class:`ntq_jax.types.PlanStatus`;
* ``stages (S,)`` names and ``timings (S,)`` seconds of the chunk's stages
  (:data:`STAGES`; the file's own ``write`` entry is 0, the report has it), and ``fingerprint``:
  the digest of every setting that made it.

Any chunk can therefore be (re)made on its own, in any order or process, with
the same content. A chunk file whose fingerprint matches is skipped, so an
interrupted run resumes where it stopped without planning a finished chunk
again; a missing, corrupt or foreign (other settings) chunk is made again.
Memory does not grow with ``n_queries``: one chunk is held at a time, and the
returned :class:`StreamReport` keeps per-stage sums only. Progress bars are
passed in (:mod:`ntq_jax.progress`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import jax
import numpy as np

from ntq_jax import artifacts
from ntq_jax.progress import Progress, open_bar
from ntq_jax.queries import (
    NON_TRIVIAL,
    NT_EXHAUSTED,
    UNIFORM,
    sample_nontrivial_queries,
    sample_uniform_queries,
)
from ntq_jax.types import PlanStatus

__all__ = [
    "STAGES",
    "STREAM_VERSION",
    "StreamReport",
    "chunk_spans",
    "chunk_queries",
    "chunk_fingerprint",
    "chunk_path",
    "make_chunk",
    "stream_chunks",
]

STREAM_VERSION = 1  # bump when a chunk made from the same settings changes
STAGES = ("sample", "build", "search", "shortcut", "verify", "write")


@dataclass
class StreamReport:
    """What :func:`stream_chunks` did: chunk indices ``planned`` (made now) and
    ``skipped`` (already complete); queries and solved queries of the planned
    chunks; per-stage seconds summed over the planned chunks."""

    planned: list = field(default_factory=list)
    skipped: list = field(default_factory=list)
    queries: int = 0
    solved: int = 0
    seconds: dict = field(default_factory=lambda: {s: 0.0 for s in STAGES})


def chunk_spans(n_queries: int, chunk: int) -> list[tuple[int, int]]:
    """The ``(start, stop)`` query ranges of the chunks (the last may be shorter)."""
    if int(chunk) < 1 or int(n_queries) < 0:
        raise ValueError(f"need chunk >= 1 and n_queries >= 0, got {chunk}, {n_queries}")
    return [(a, min(a + int(chunk), int(n_queries))) for a in range(0, int(n_queries), int(chunk))]


def chunk_queries(
    env, seed: int, index: int, n: int, padding: float, n_max: int = 1000
) -> tuple[np.ndarray, np.ndarray]:
    """Chunk ``index``'s ``n`` queries ``((n, 2, d) float32, kind (n,) int8)``: ``n // 2``
    uniform then ``n - n // 2`` non-trivial, from ``fold_in(key(seed), index)`` only."""
    k_u, k_nt = jax.random.split(jax.random.fold_in(jax.random.key(int(seed)), int(index)))
    n_u = int(n) // 2
    q = np.zeros((int(n), 2, env.robot.dim), np.float32)
    kind = np.full(int(n), UNIFORM, np.int8)
    if n_u:
        q[:n_u] = sample_uniform_queries(env.robot, env.world, k_u, n_u, padding)
    if n - n_u:
        q_nt, exhausted = sample_nontrivial_queries(
            env.robot, env.world, k_nt, n - n_u, padding, n_max
        )
        q[n_u:] = q_nt
        kind[n_u:] = np.where(exhausted, NT_EXHAUSTED, NON_TRIVIAL)
    return q, kind


def chunk_fingerprint(
    env, *, seed: int, index: int, n: int, padding: float, check: str, options: dict
) -> str:
    """The digest of everything chunk ``index`` depends on."""
    return artifacts.fingerprint(
        {
            "version": STREAM_VERSION,
            "env": env.to_json(),
            "seed": int(seed),
            "index": int(index),
            "n": int(n),
            "padding": float(padding),
            "check": check,
            "options": {
                k: v for k, v in sorted(options.items()) if k not in ("threads", "cache_dir")
            },
        }
    )


def chunk_path(out: str | Path, index: int) -> Path:
    """The file of chunk ``index`` in ``out``."""
    return Path(out) / f"chunk_{int(index):06d}.npz"


def make_chunk(
    env,
    out: str | Path,
    *,
    seed: int,
    index: int,
    n: int,
    padding: float,
    check: str = "certified",
    options: dict | None = None,
) -> dict:
    """Samples, plans, verifies and atomically writes chunk ``index``; returns its arrays."""
    from ntq_jax.planners.roadmap import plan_roadmap

    options = dict(options or {})
    fp = chunk_fingerprint(
        env, seed=seed, index=index, n=n, padding=padding, check=check, options=options
    )
    t0 = time.perf_counter()
    q, kind = chunk_queries(env, seed, index, n, padding)
    t1 = time.perf_counter()
    res = plan_roadmap(env, q, padding=padding, check=check, **options)
    info = res.info
    t2 = time.perf_counter()
    times = {
        "sample": t1 - t0,
        "build": info["build_time"],
        "search": info["search_time"],
        "shortcut": info["smooth_time"],
        "verify": info["check_time"],
    }
    # what plan_roadmap spent outside its timed stages goes to the search
    times["search"] += max(0.0, (t2 - t1) - sum(times[s] for s in STAGES[1:5]))
    arrays = {
        "queries": q,
        "kind": kind,
        "paths": np.asarray(res.paths, np.float32),
        "lengths": np.asarray(res.lengths, np.int32),
        "costs": np.asarray(res.costs, np.float64),
        "status": np.asarray(res.status, np.int8),
        "stages": np.array(STAGES),
        "fingerprint": np.array(fp),
    }
    t3 = time.perf_counter()
    times["write"] = 0.0
    arrays["timings"] = np.array([times[s] for s in STAGES], np.float64)
    artifacts.save_npz(chunk_path(out, index), **arrays)
    arrays["timings"][-1] = time.perf_counter() - t3  # the write itself, for the report
    return arrays


def stream_chunks(
    env,
    out: str | Path,
    *,
    n_queries: int,
    chunk: int = 10_000,
    seed: int = 0,
    padding: float | None = None,
    check: str = "certified",
    options: dict | None = None,
    max_chunks: int | None = None,
    shard: tuple[int, int] = (0, 1),
    progress: Progress = None,
) -> StreamReport:
    """Makes the missing chunks of ``n_queries`` queries in ``out`` (see the module).

    Args:
        env: the environment.
        out: the folder of the chunk files (created).
        n_queries: queries in all; ``chunk``: queries per chunk file.
        seed: the seed of the query stream.
        padding: planning clearance (None: the environment's).
        check: motion check of planning and verification (``"certified"`` or
            ``"discretized"``).
        options: further :func:`~ntq_jax.planners.roadmap.plan_roadmap` options
            (``threads`` and ``cache_dir`` do not change a chunk's content).
        max_chunks: stop after making this many chunks (None: all).
        shard: ``(w, W)``: only chunks with ``index % W == w`` (one of W workers).
        progress: a bar over the queries (``initial`` counts the complete ones).

    Returns:
        A :class:`StreamReport`.
    """
    padding = env.resolve_padding(padding)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    artifacts.clean_tmp(out)
    w, n_w = (int(v) for v in shard)
    spans = [(i, a, b) for i, (a, b) in enumerate(chunk_spans(n_queries, chunk)) if i % n_w == w]
    rep = StreamReport()
    todo = []
    for i, a, b in spans:
        fp = chunk_fingerprint(
            env,
            seed=seed,
            index=i,
            n=b - a,
            padding=padding,
            check=check,
            options=dict(options or {}),
        )
        if _complete(chunk_path(out, i), fp):
            rep.skipped.append(i)
        else:
            todo.append((i, a, b))
    done = sum(b - a for _, a, b in spans) - sum(b - a for _, a, b in todo)
    with open_bar(
        progress,
        desc=f"{env.name}: stream",
        total=sum(b - a for _, a, b in spans),
        unit="query",
        initial=done,
    ) as bar:
        for i, a, b in todo[:max_chunks]:
            got = make_chunk(
                env, out, seed=seed, index=i, n=b - a, padding=padding, check=check, options=options
            )
            rep.planned.append(i)
            rep.queries += b - a
            rep.solved += int((got["status"] == PlanStatus.SOLVED).sum())
            for s, t in zip(STAGES, got["timings"]):
                rep.seconds[s] += float(t)
            bar.update(b - a)
            bar.set_postfix_str(f"solved {rep.solved}/{rep.queries}")
    return rep


def _complete(path: Path, fp: str) -> bool:
    """Whether ``path`` is a readable chunk file made with fingerprint ``fp``."""
    if not path.is_file():
        return False
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["fingerprint"]) != fp:
                return False
            return all(z[k] is not None for k in z.files)  # reads (and CRC-checks) every array
    except Exception:  # noqa: BLE001 - a corrupt or partial file is made again
        return False
