"""Shortcutting: the host rounds of ``shortcut_paths`` against the jitted ``while_loop`` core.

    python benchmarks/bench_shortcut.py --env rigid/0 --env nlink/6 --paths 3000

Per map: ``--paths`` roadmap queries (half non-trivial, ``env.sample_queries``) planned
without shortcutting; then, in this one process, both implementations of the greedy
rule on the same raw paths:

``host``
    :func:`ntq_jax.planners.smoothing.shortcut_paths`: rounds of
    :func:`ntq_jax.robots.batch.steer_to_pairs` (its program is already compiled by
    the planning's own checks, as in every pipeline).
``jitted``
    :func:`ntq_jax.planners.smoothing.shortcut` (the traceable core) over chunks of 128
    paths with the path buffer padded to a power of two >= 16, the way
    ``shortcut_paths`` ran before.

Prints the first call (the jitted core compiles its own program there), the median
of ``--reps`` interleaved warm repeats, their ratio, and whether the two give the same
waypoints, lengths and flags.
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np
from common import interleaved

import ntq_jax as nj
from ntq_jax.batching import bucket_size, padded_chunks
from ntq_jax.planners.smoothing import shortcut, shortcut_paths


def jitted(env, paths, lengths, padding, chunk=128):
    """The traceable core over fixed-size chunks (the earlier ``shortcut_paths``)."""
    bsz, _, d = paths.shape
    lp = bucket_size(int(lengths.max()), 16)
    buf = np.full((bsz, lp, d), np.nan, np.float32)
    w = min(lp, paths.shape[1])
    buf[:, :w] = paths[:, :w]
    parts = [
        (m, shortcut(env.robot, env.world, b, n, padding))
        for _, m, (b, n), _ in padded_chunks([buf, lengths.astype(np.int32)], chunk, fill=0)
    ]
    out, n_out, ok = (np.concatenate([np.asarray(r[i])[:m] for m, r in parts]) for i in range(3))
    width = max(2, int(n_out.max()))
    return out[:, :width], n_out, ok


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "--env", action="append", default=None, help="preset (repeatable; default rigid/0 nlink/6)"
    )
    ap.add_argument("--paths", type=int, default=3000)
    ap.add_argument("--reps", type=int, default=5)
    args = ap.parse_args()
    print(
        "| map | paths | mean waypoints raw -> shortcut | host first call | jitted first call "
        "| host warm | jitted warm | jitted / host (warm) | same output |"
    )
    print("|---|---:|---|---:|---:|---:|---:|---:|---|")
    for name in args.env or ["rigid/0", "nlink/6"]:
        env = nj.make_env(name)
        q, _ = env.sample_queries(jax.random.key(1), args.paths, 0.5)
        raw = nj.plan(
            env, np.asarray(q), "roadmap", smooth=False
        )  # compiles steer_to_pairs' program
        keep = raw.lengths > 0
        paths, lengths, pad = raw.paths[keep], raw.lengths[keep], float(env.padding)
        t0 = time.perf_counter()
        h = shortcut_paths(env.robot, env.world, paths, lengths, pad)
        t1 = time.perf_counter()
        j = jitted(env, paths, lengths, pad)
        t2 = time.perf_counter()
        same = all(np.array_equal(a, b, equal_nan=True) for a, b in zip(h, j))
        warm = interleaved(
            {
                "host": lambda: shortcut_paths(env.robot, env.world, paths, lengths, pad),
                "jitted": lambda: jitted(env, paths, lengths, pad),
            },
            args.reps,
        )
        print(
            f"| {name} | {len(lengths)} | {lengths.mean():.1f} -> {h[1].mean():.2f} | {t1 - t0:.2f} s "
            f"| {t2 - t1:.2f} s | {warm['host']:.3f} s | {warm['jitted']:.3f} s "
            f"| {warm['jitted'] / warm['host']:.2f}x | {'yes' if same else 'NO'} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
