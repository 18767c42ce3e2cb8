"""The public batched calls cost at most a quarter more than their own compiled kernels.

A guard that no machine's speed can fool: ``Env.steer_to`` (point robot, rigid body,
arm) and ``Env.is_valid`` are timed against the bare kernel of
:mod:`ntq_jax.robots.batch` on the same rows in the same process (repeats
interleaved, the median of the per-repeat ratios), device arrays and NumPy input
alike, at the sizes where a wrapper goes wrong: 1, 63, 64, 65 (one edge bucket),
2^20 and 2^20 + 1 (one piece, one piece and an edge) and about 10^7 (many pieces).
The bare kernel runs on exactly the rows (a program compiled for that size), or,
below ``PIECE_MIN``, on the rows already padded to the public call's bucket; it gets
them as the public call does (device arrays, or NumPy arrays that the jitted call
transfers itself).

From 2^20 rows on, the public call may cost at most 1.25x the bare kernel. Below
(``PIECE_MIN`` rows, one edge bucket), a cheap kernel (the point robot's exact test,
``is_valid``) takes about one dispatch whatever the size, and the public call makes
up to three (pad on the device, check, take the first rows) plus its argument
checks: there the bound is 6x (about 3x measured by benchmarks/bench_wrapper.py;
the rigid body's and the arm's motion checks cost more than a dispatch and stay
nearer 1x). Public and bare calls alternate call by call, so a burst of other work
on the shared machine lands on both sides of a ratio. The arm and the rigid body
check short motions (a few states each) and their ``is_valid`` runs on 10^7 states:
the cheapest work, where a wrapper's overhead shows most.
"""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ntq_jax as nj
from ntq_jax.batching import fine_bucket_size
from ntq_jax.robots import batch as B
from ntq_jax.robots.rows import PIECE_MIN

SMALL = (1, 63, 64, 65)
LARGE = (1 << 20, (1 << 20) + 1, 10_000_003)
REPS = 7
#: Calls per timing below ``PIECE_MIN`` rows (a call there takes tens of microseconds).
SMALL_CALLS = 16


def _ratio(public, bare, reps: int = REPS, calls: int = 1) -> float:
    """Median over repeats of public time / bare time (after a warm-up), each repeat
    summing ``calls`` alternating pairs (a public call, then a bare one): calls of tens of
    microseconds (the small batches) are timed by the dozen, and alternating call by call
    puts a burst of other work (the other core's, the machine's neighbours') on both sides
    of the ratio, not on a block of calls of one kind."""
    jax.block_until_ready(public()), jax.block_until_ready(bare())
    ratios = []
    for _ in range(reps):
        t_public = t_bare = 0.0
        for _ in range(calls):
            t0 = time.perf_counter()
            jax.block_until_ready(public())
            t1 = time.perf_counter()
            jax.block_until_ready(bare())
            t_public, t_bare = t_public + t1 - t0, t_bare + time.perf_counter() - t1
        ratios.append(t_public / t_bare)
    return float(np.median(ratios))


def _rows(env, n: int, seed: int):
    rng = np.random.default_rng(seed)
    lo, hi = (np.asarray(v, np.float64) for v in env.robot.config_bounds(env.world))
    a = (lo + rng.random((n, env.dim)) * (hi - lo)).astype(np.float32)
    if env.robot.kind == "point":
        b = (lo + rng.random((n, env.dim)) * (hi - lo)).astype(np.float32)
    else:  # short motions: a few checked states each, the cheapest steer_to work
        b = np.clip(a + np.float32(0.01), lo, hi).astype(np.float32)
    return a, b


def _bare_input(x: np.ndarray) -> np.ndarray:
    n = x.shape[0]
    m = fine_bucket_size(n, 64) if n < PIECE_MIN else n
    return x if m == n else np.pad(x, ((0, m - n), (0, 0)))


def _check(public, bare, x_args, bare_args, n: int, what: str):
    want = np.asarray(bare(*bare_args))[:n]
    got = np.asarray(public(*x_args))
    # Random float states: a row within float32 rounding of contact may get the other
    # answer where the compiled loop contracts multiply-adds differently at another offset
    # (BENCHMARKS.md, "steer_to with NumPy input"); at most 2 such rows in 10^7. The
    # dyadic maps of tests/test_envs.py check exact equality.
    assert got.shape == want.shape and np.sum(got != want) <= n // 5_000_000, what
    bound = 1.25 if n >= 1 << 20 else 6.0
    calls = 1 if n >= PIECE_MIN else SMALL_CALLS
    ratio = _ratio(lambda: public(*x_args), lambda: bare(*bare_args), calls=calls)
    for _ in range(3):  # up to three more rounds, a second apart: bursts on the shared machine
        if ratio <= bound:
            break
        time.sleep(1.0)
        ratio = min(ratio, _ratio(lambda: public(*x_args), lambda: bare(*bare_args), calls=calls))
    assert ratio <= bound, f"{what}: public / bare = {ratio:.2f} > {bound}"


@pytest.mark.parametrize("name", ["point/3", "rigid/0", "nlink/4"])
def test_steer_to_costs_little_more_than_its_kernel(name):
    env = nj.make_env(name)
    sizes = SMALL + (LARGE if env.robot.kind == "point" else ())
    for n in sizes:
        a, b = _rows(env, n, seed=n % 1000)
        ap, bp = _bare_input(a), _bare_input(b)
        da, db, dap, dbp = jax.block_until_ready([jnp.asarray(v) for v in (a, b, ap, bp)])
        bare = lambda x, y: B.steer_to_batch(env.robot, env.world, x, y, 0.0)  # noqa: E731
        public = lambda x, y: env.steer_to(x, y, padding=0)  # noqa: E731
        for kind, args, bare_args in (
            ("device", (da, db), (dap, dbp)),
            ("numpy", (a, b), (ap, bp)),
        ):
            _check(public, bare, args, bare_args, n, f"{name} steer_to {kind} n={n}")


@pytest.mark.parametrize("name", ["rigid/0", "nlink/4"])
def test_is_valid_costs_little_more_than_its_kernel(name):
    env = nj.make_env(name)
    for n in SMALL + LARGE:
        a, _ = _rows(env, n, seed=n % 1000)
        ap = _bare_input(a)
        da, dap = jax.block_until_ready([jnp.asarray(a), jnp.asarray(ap)])
        bare = lambda x: B.is_valid_batch(env.robot, env.world, x, 0.0)  # noqa: E731
        public = lambda x: env.is_valid(x, padding=0)  # noqa: E731
        for kind, args, bare_args in (("device", (da,), (dap,)), ("numpy", (a,), (ap,))):
            _check(public, bare, args, bare_args, n, f"{name} is_valid {kind} n={n}")
