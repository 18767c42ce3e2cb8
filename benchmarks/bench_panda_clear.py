#!/usr/bin/env python
"""The Panda's validity test with the obstacle comparison in squared form, against distances.

``SerialArm.is_valid`` asks ``geometry.spheres_clear`` whether each collision sphere is
clear of every obstacle, comparing squared distances; the baseline is the same arm with
that one line as it was, ``spheres_clearance(...) > 0`` (a signed distance per sphere
and obstacle, one square root each). Side by side in one process, per scene (problem 1),
repeats interleaved, medians of process CPU seconds (``time.process_time``, the figure
to trust when the machine is shared; run it on one core):

* ``is_valid``: the jitted, vmapped kernel on ``--states`` uniform configurations;
* ``steer_to``: the discretised check's work queue (``discretized_steer_to_batch``, the
  lanes ``Env.steer_to`` uses) on ``--motions`` motions between uniform valid states.

Both sides' answers must be identical (they can differ only for a sphere within float32
rounding of touching); the script exits 1 otherwise.

    taskset -c 0 python benchmarks/bench_panda_clear.py
    taskset -c 0 python benchmarks/bench_panda_clear.py --scene cage --states 262144
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

import ntq_jax as nj
from ntq_jax.geometry import spheres_clearance
from ntq_jax.robots.base import discretized_steer_to_batch
from ntq_jax.robots.serial_arm import QUEUE_LANES, SerialArm
from ntq_jax.scenes.mbm import SCENES


@dataclasses.dataclass(frozen=True)
class DistanceArm(SerialArm):
    """The baseline: ``is_valid`` with the obstacle test through signed distances."""

    def is_valid(self, q, world, padding):
        x, y, z = self._sphere_xyz(q)
        radii = jnp.asarray(self.sphere_radii, jnp.float32)
        clear = spheres_clearance(jnp.stack([x, y, z], axis=1), radii, world, padding) > 0.0
        return self._q_ok(q) & jnp.all(clear) & self._self_free(x, y, z)


def cpu_medians(cases: dict, reps: int) -> dict:
    """Median CPU seconds of each case, repeats interleaved (after one warm-up each)."""
    for fn in cases.values():
        jax.block_until_ready(fn())
    got = {k: [] for k in cases}
    for _ in range(reps):
        for k, fn in cases.items():
            c0 = time.process_time()
            jax.block_until_ready(fn())
            got[k].append(time.process_time() - c0)
    return {k: float(np.median(v)) for k, v in got.items()}


def scene_rows(scene: str, args) -> tuple[list[str], bool]:
    env = nj.make_env(f"panda/{scene}/1")
    arm, world, pad = env.robot, env.world, env.padding
    base = DistanceArm(**{f.name: getattr(arm, f.name) for f in dataclasses.fields(arm) if f.init})
    lo, hi = (np.asarray(v) for v in arm.config_bounds())
    rng = np.random.default_rng(args.seed)
    q = jnp.asarray(rng.uniform(lo, hi, (args.states, arm.dim)).astype(np.float32))
    pool = rng.uniform(lo, hi, (8 * args.motions, arm.dim)).astype(np.float32)
    pool = pool[np.asarray(env.is_valid(pool))]
    a, b = jnp.asarray(pool[: args.motions].T), jnp.asarray(pool[args.motions : 2 * args.motions].T)

    def valid(robot):
        return jax.jit(jax.vmap(lambda s: robot.is_valid(s, world, pad)))

    def steer(robot):
        return jax.jit(
            lambda x, y: discretized_steer_to_batch(
                robot, x, y, world, pad, robot.resolution, lanes=QUEUE_LANES
            )
        )

    kernels = {
        ("is_valid", "squared"): (valid(arm), (q,)),
        ("is_valid", "distances"): (valid(base), (q,)),
        ("steer_to", "squared"): (steer(arm), (a, b)),
        ("steer_to", "distances"): (steer(base), (a, b)),
    }
    same = True
    for what in ("is_valid", "steer_to"):
        new, old = (
            np.asarray(kernels[(what, k)][0](*kernels[(what, k)][1]))
            for k in ("squared", "distances")
        )
        same &= bool(np.array_equal(new, old))
    cases = {k: (lambda f=f, x=x: f(*x)) for k, (f, x) in kernels.items()}
    sec = cpu_medians(cases, args.reps)
    n = {"is_valid": args.states, "steer_to": args.motions}
    rows = []
    for what in ("is_valid", "steer_to"):
        new, old = sec[(what, "squared")], sec[(what, "distances")]
        unit = "configurations" if what == "is_valid" else "motions"
        rows.append(
            f"{scene:17s} {what:9s} squared {n[what] / new:11,.0f} {unit}/cpu-s   distances "
            f"{n[what] / old:11,.0f}   {old / new:.2f}x"
        )
    return rows, same


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", action="append", choices=SCENES, help="repeatable; default all")
    p.add_argument("--states", type=int, default=1 << 16)
    p.add_argument("--motions", type=int, default=2048)
    p.add_argument("--reps", type=int, default=5)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    ok = True
    for scene in args.scene or SCENES:
        rows, same = scene_rows(scene, args)
        print("\n".join(rows) + ("" if same else "   ANSWERS DIFFER"), flush=True)
        ok &= same
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
