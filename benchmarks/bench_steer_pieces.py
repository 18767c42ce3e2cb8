#!/usr/bin/env python
"""Where the public point ``steer_to`` loses to one whole-batch program on a large batch.

Side by side in one process on the same uniform device-array pairs of point/3 (padding
0; repeats interleaved, medians of ``--reps``; both cores should be free):

* ``whole``: the bare kernel compiled for exactly the batch (one program per batch
  size: the rate a per-size compilation would give);
* ``pieces 2^k``: the same kernel on in-place host pieces of ``2^k`` rows, dispatched
  asynchronously, nothing joined (over the first ``2^floor(log2 N)`` rows, so every
  size divides them);
* ``public, pieces up to 2^k``: ``Env.steer_to`` with ``ntq_jax.robots.rows.PIECE_MAX``
  set to ``2^k`` (its pieces, edge and join);
* ``host join``: the public call's pieces joined into a NumPy array on the host;
* ``donated update``: each piece checked inside a program that writes its answers into
  one donated output (``dynamic_update_slice``), instead of a join.

Every variant's answers are compared with ``whole``'s. Rates are pairs per second
(queries / median wall seconds).

    python benchmarks/bench_steer_pieces.py              # 10^7 pairs, 9 interleaved repeats
    python benchmarks/bench_steer_pieces.py --n 2e7 --reps 5
"""

from __future__ import annotations

import argparse
import functools

import jax
import jax.numpy as jnp
import numpy as np
from common import interleaved

import ntq_jax as nj
from ntq_jax.robots import batch, rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=float, default=1e7, help="pairs (default 10^7)")
    ap.add_argument("--reps", type=int, default=9, help="interleaved repeats (medians)")
    args = ap.parse_args()
    n = int(args.n)
    env = nj.make_env("point/3")
    robot, world = env.robot, env.world
    rng = np.random.default_rng(0)
    lo, hi = np.asarray(world.bounds)[:, 0], np.asarray(world.bounds)[:, 1]
    a = (lo + rng.random((n, 2)) * (hi - lo)).astype(np.float32)
    b = (lo + rng.random((n, 2)) * (hi - lo)).astype(np.float32)
    da, db = jax.block_until_ready((jnp.asarray(a), jnp.asarray(b)))
    ha, hb = np.asarray(da), np.asarray(db)  # the device buffers' host views
    p2 = 1 << (n.bit_length() - 1)  # the largest power of two <= n

    def kernel(x, y, size):
        return batch._steer_masked(robot, world, x, y, rows._all_rows(size), 0.0, "discretized")

    def pieces(k):
        size = 1 << k
        return lambda: [
            kernel(ha[i : i + size], hb[i : i + size], size) for i in range(0, p2, size)
        ]

    def public(k):
        def call():
            rows.PIECE_MAX = 1 << k
            return env.steer_to(da, db, padding=0)

        return call

    plan = batch._flexible([ha, hb], robot)

    def host_join():
        rows.PIECE_MAX = default_max
        return rows.run_rows(
            lambda x, y, m: batch._steer_masked(robot, world, x, y, m, 0.0, "discretized"),
            [ha, hb],
            plan,
            host=True,
        )

    @functools.partial(jax.jit, donate_argnums=0, static_argnames=("start",))
    def write(out, x, y, start):
        got = batch.steer_to_cm(robot, world, x.T, y.T, 0.0)
        return jax.lax.dynamic_update_slice(out, got, (start,))

    def donated():
        out = jnp.zeros((n,), bool)
        for start, size in plan.pieces:
            out = write(out, ha[start : start + size], hb[start : start + size], start)
        return out

    default_max = rows.PIECE_MAX
    cases = {"whole": lambda: kernel(da, db, n)}
    cases.update({f"pieces 2^{k}": pieces(k) for k in (18, 20, 22) if (1 << k) <= p2})
    cases.update({f"public, pieces up to 2^{k}": public(k) for k in (20, 22, 23)})
    cases["host join"] = host_join
    cases["donated update"] = donated
    ref = np.asarray(cases["whole"]())
    covered = plan.tail  # rows the donated variant writes (the edge is not its subject)
    for name, fn in cases.items():
        got = fn()
        got = np.concatenate([np.asarray(g) for g in got]) if isinstance(got, list) else got
        m = covered if name == "donated update" else len(np.asarray(got))
        if not np.array_equal(np.asarray(got)[:m], ref[:m]):
            raise SystemExit(f"{name}: answers differ from the whole-batch kernel's")
    times = interleaved(cases, args.reps)
    rows.PIECE_MAX = default_max
    base = n / times["whole"]
    print(f"point/3, {n:,} device pairs, padding 0; medians of {args.reps} interleaved repeats")
    for name, sec in times.items():
        count = p2 if name.startswith("pieces") else n
        rate = count / sec
        print(
            f"{name:28s} {rate / 1e6:8.0f} M/s  {rate / base:5.2f}x whole  cores {interleaved.cores[name]:.2f}"
        )


if __name__ == "__main__":
    main()
