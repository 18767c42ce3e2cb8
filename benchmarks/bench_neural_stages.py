"""The neural planner on the Panda: its check stages on the host (shared programs) vs fused.

``ntq_jax.neural.host_stages`` runs the planner's checks for a robot with
``shared_check_programs`` (the 3-D arm) through the package's shared batched programs;
``Stages.on_host = False`` runs the fused stages the planar robots use. Both plan the
same queries in one process, and the script prints, for each, the first call (compiling
included; the host path pays for its shared programs here, which a pipeline's data stage
has usually compiled already) and the median of later calls, their ratios, and whether
every output array is equal.

    python benchmarks/bench_neural_stages.py [--env panda/table_pick/1] [--queries 256]
        [--check certified] [--reps 5]

The PNet is a stand-in (a step towards the goal with noise of the key), so no training
is needed; the options are those of the Panda configs' evaluation with replanning.
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np
from common import interleaved
from jax.tree_util import Partial

import ntq_jax as nj
from ntq_jax.neural import PlannerOptions, plan_batch, steps
from ntq_jax.queries import sample_uniform_queries

FIELDS = ("paths", "lengths", "success", "costs", "cause", "pnet_calls", "replans")


def _wander(key, cur, goal):
    return cur + 0.3 * (goal - cur) + jax.random.normal(key, cur.shape) * 0.15


def _planner(env, q, opts, host: bool):
    init = steps.Stages.__init__

    def run():
        def patched(self, *a, **k):
            init(self, *a, **k)
            self.on_host = host

        steps.Stages.__init__ = patched
        try:
            return plan_batch(env, Partial(_wander), q, jax.random.key(4), opts)
        finally:
            steps.Stages.__init__ = init

    return run


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--env", default="panda/table_pick/1")
    ap.add_argument("--queries", type=int, default=256)
    ap.add_argument("--check", default="certified", choices=("discretized", "certified"))
    ap.add_argument("--reps", type=int, default=5)
    args = ap.parse_args()
    env = nj.make_env(args.env)
    q = sample_uniform_queries(env.robot, env.world, jax.random.key(9), args.queries, 0.0)
    q = np.asarray(q, np.float32)
    opts = PlannerOptions(n_plan=30, replan_rounds=3, replan_steps=10, eval_check=args.check)
    runs = {"host": _planner(env, q, opts, True), "fused": _planner(env, q, opts, False)}
    first, got = {}, {}
    for name, fn in runs.items():
        t0 = time.perf_counter()
        got[name] = fn()
        first[name] = time.perf_counter() - t0
    later = interleaved({k: (lambda fn=fn: fn().success) for k, fn in runs.items()}, args.reps)
    equal = all(
        np.array_equal(getattr(got["host"], f), getattr(got["fused"], f), equal_nan=True)
        for f in FIELDS
    )
    print(f"{args.env}, {args.queries} queries, {args.check} check, replanning")
    for name in runs:
        print(
            f"  {name:5s}: first call {first[name]:6.1f} s, later calls {later[name]:6.3f} s "
            f"(median of {args.reps}); solved {int(got[name].success.sum())}"
        )
    print(
        f"  fused / host: first call {first['fused'] / first['host']:.2f}x, "
        f"later calls {later['fused'] / later['host']:.2f}x; every output array equal: {equal}"
    )


if __name__ == "__main__":
    main()
