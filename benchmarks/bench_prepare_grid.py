"""The A* planner's per-grid tables: host NumPy :func:`prepare_grid` against a jitted JAX build.

    python benchmarks/bench_prepare_grid.py [--shape 60x90 --shape 256x256 ...] [--reps 5]

``jax_prepare`` is the jitted JAX build of the same tables (``lax.scan`` per line,
pointer-jumping components), kept here as the baseline. For each grid shape (random
boxes, about 30 % occupied) it prints the first call on a new shape (the JAX build
compiles; both run once) and the median of ``--reps`` interleaved repeated calls, with
their ratios, after checking that both give the same ``occ``, ``jump`` and ``label``.
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np
from common import interleaved
from jax import lax

from ntq_jax.planners.grid_graph import DIRS, GridGraph, direction_index, prepare_grid


def _shift(a, dr, dc, fill):
    h, w = a.shape
    return lax.dynamic_slice(jnp.pad(a, 1, constant_values=fill), (1 + dr, 1 + dc), (h, w))


def _scan_lines(can_move, event, dr, dc):
    if dr == 0:
        return _scan_lines(can_move.T, event.T, dc, 0).T

    def step(prev, xs):
        cm, ev = xs
        nxt = _shift(prev[None], 0, dc, 0)[0] if dc else prev
        row = jnp.where(cm, jnp.where(ev, 1, jnp.where(nxt > 0, nxt + 1, nxt - 1)), 0)
        return row, row

    zero = jnp.zeros(can_move.shape[1], jnp.int32)
    if dr < 0:
        return lax.scan(step, zero, (can_move, event))[1]
    return lax.scan(step, zero, (can_move[::-1], event[::-1]))[1][::-1]


def _jump_tables(free):
    tables = [None] * 8
    for k in range(4):
        dr, dc = (int(x) for x in DIRS[k])
        pr, pc = dc, dr
        forced = (_shift(free, dr + pr, dc + pc, False) & ~_shift(free, pr, pc, False)) | (
            _shift(free, dr - pr, dc - pc, False) & ~_shift(free, -pr, -pc, False)
        )
        tables[k] = _scan_lines(_shift(free, dr, dc, False), forced, dr, dc)
    for k in range(4, 8):
        dr, dc = (int(x) for x in DIRS[k])
        kv, kh = direction_index(dr, 0), direction_index(0, dc)
        can = _shift(free, dr, dc, False) & _shift(free, dr, 0, False) & _shift(free, 0, dc, False)
        event = _shift((tables[kv] > 0) | (tables[kh] > 0), dr, dc, False)
        tables[k] = _scan_lines(can, event, dr, dc)
    return jnp.where(free[None], jnp.stack(tables), 0)


def _components(free):
    h, w = free.shape
    hw = h * w
    big = jnp.int32(hw)
    lab0 = jnp.where(free, jnp.arange(hw, dtype=jnp.int32).reshape(h, w), big)

    def body(state):
        lab, _ = state
        m = lab
        for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
            m = jnp.minimum(m, _shift(lab, dr, dc, big))
        m = jnp.where(free, m, big).reshape(-1)
        m = jnp.where(m < big, jnp.minimum(m, m[jnp.minimum(m, hw - 1)]), big).reshape(h, w)
        return m, jnp.any(m != lab)

    return lax.while_loop(lambda s: s[1], body, (lab0, jnp.bool_(True)))[0].reshape(-1)


@jax.jit
def jax_prepare(occ) -> GridGraph:
    free = ~occ
    jump = _jump_tables(free).reshape(8, -1).T.astype(jnp.int16)
    return GridGraph(occ=occ, jump=jump, label=_components(free))


def random_boxes(h: int, w: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    occ = np.zeros((h, w), bool)
    while occ.mean() < 0.3:
        r, c = rng.integers(0, h), rng.integers(0, w)
        occ[r : r + rng.integers(1, max(2, h // 8)), c : c + rng.integers(1, max(2, w // 8))] = True
    return occ


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--shape", action="append", help="HxW (repeatable); default 60x90, 256x256, 1024x1024"
    )
    ap.add_argument("--reps", type=int, default=5)
    args = ap.parse_args()
    for shape in args.shape or ["60x90", "256x256", "1024x1024"]:
        h, w = (int(x) for x in shape.split("x"))
        occ = random_boxes(h, w)
        first = {}
        for name, fn in (
            ("jax_prepare", lambda: jax_prepare(jnp.asarray(occ))),
            ("prepare_grid", lambda: prepare_grid(occ)),
        ):
            t0 = time.perf_counter()
            out = jax.block_until_ready(fn())
            first[name] = (time.perf_counter() - t0, out)
        a, b = first["jax_prepare"][1], first["prepare_grid"][1]
        for field in GridGraph._fields:
            x, y = np.asarray(getattr(a, field)), np.asarray(getattr(b, field))
            assert x.dtype == y.dtype and np.array_equal(x, y), (shape, field)
        med = interleaved(
            {
                "jax_prepare": lambda: jax_prepare(jnp.asarray(occ)),
                "prepare_grid": lambda: prepare_grid(occ),
            },
            args.reps,
        )
        print(
            f"{shape}: first call jax_prepare {first['jax_prepare'][0]:.2f} s, prepare_grid "
            f"{first['prepare_grid'][0]:.3f} s (ratio {first['prepare_grid'][0] / first['jax_prepare'][0]:.3f}); "
            f"repeated (median of {args.reps}) jax_prepare {med['jax_prepare'] * 1e3:.1f} ms, "
            f"prepare_grid {med['prepare_grid'] * 1e3:.1f} ms "
            f"(ratio {med['prepare_grid'] / med['jax_prepare']:.2f}); same tables"
        )


if __name__ == "__main__":
    main()
