#!/usr/bin/env python
"""Plans one query with a trained PNet of a run folder; prints the path and its cost, draws a PNG.

Examples::

    python scripts/plan.py --run runs/point-1a2b3c4d --model 3 --start 1 1 --goal 18 18
    python scripts/plan.py --run RUN --env point/2 --model 0 --start 2 2 --goal 18 2 --no-steer
    python scripts/plan.py --run RUN --env rigid/1 --model 3 --start 1 1 0 --goal 9 9 1.57

The start and goal are states in the robot's coordinates (x y for the point
robot, x y theta for the rigid body, joint angles for the arm). A state out of
bounds or in collision (on the evaluation geometry, padding 0) is refused with
an error naming it. The PNG (default ``<run>/figures/plan_<env>_PNet_<m>.png``)
shows the map, the neural path and, for point robots, the exact optimum.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

import ntq_jax as nj
from ntq_jax import artifacts
from ntq_jax.experiment.cli import UsageError, check_writable, run_cli, seed_arg


class PlanError(UsageError):
    """An expected failure of this script: reported as one ``error:`` line, exit code 2."""


def _load(run: Path, env_name: str | None):
    from ntq_jax import make_env
    from ntq_jax.envs import env_slug
    from ntq_jax.experiment import config as C

    cfg_f = run / "config.yaml"
    if not cfg_f.is_file():
        raise PlanError(
            f"{run} is not a run folder (no config.yaml); pass the folder printed by "
            "scripts/train_all.py"
        )
    cfg = C.load(cfg_f)
    if env_name is None:
        if len(cfg.envs) != 1:
            raise PlanError(
                f"the run has several environments ({', '.join(cfg.envs)}); choose one with --env"
            )
        env_name = cfg.envs[0]
    if env_name not in cfg.envs:
        raise PlanError(f"environment {env_name!r} is not in this run ({', '.join(cfg.envs)})")
    slug = env_slug(env_name)
    env_json = run / "data" / slug / "env.json"
    env = make_env(env_json if env_json.is_file() else env_name)
    return cfg, env, env_name, slug


def _check_state(env, x, what: str):
    import numpy as np

    x = np.asarray(x, np.float32)
    if x.shape != (env.dim,):
        raise PlanError(
            f"--{what} needs {env.dim} numbers for the {env.robot.kind} robot of "
            f"{env.name}, got {x.size}"
        )
    if not np.all(np.isfinite(x)):
        raise PlanError(f"--{what} {x.tolist()} is not finite")
    lo, hi = (np.asarray(b) for b in env.robot.config_bounds(env.world))
    if np.any(x < lo) or np.any(x > hi):
        raise PlanError(
            f"--{what} {x.tolist()} is out of bounds: each coordinate must lie in "
            f"[{', '.join(f'{a:g}..{b:g}' for a, b in zip(lo, hi))}]"
        )
    if not bool(np.asarray(env.is_valid(x[None], padding=0.0))[0]):
        raise PlanError(f"--{what} {x.tolist()} is in collision with an obstacle of {env.name}")
    return x


def plan_one(
    run, model: int, start, goal, *, env_name=None, steer: bool = True, seed: int = 0, png=None
):
    """Plans one query; returns ``(result, env, png_path)`` (see the module docstring).

    Raises:
        PlanError: not a run folder, an environment not in the run, a bad state,
            a model index out of range, a corrupt ensemble, or a ``png`` path
            that cannot be written (checked before the models are loaded).
    """
    import jax
    import numpy as np

    from ntq_jax.experiment import config as C
    from ntq_jax.models import member_pnets
    from ntq_jax.neural import plan_batch
    from ntq_jax.training import CheckpointError, load_ensemble

    run = Path(run)
    cfg, env, env_name, slug = _load(run, env_name)
    s = _check_state(env, start, "start")
    g = _check_state(env, goal, "goal")
    png = Path(png) if png else run / "figures" / f"plan_{slug}_PNet_{model}.png"
    check_writable(png, "--png")  # before loading the models and planning
    if png.suffix.lower() not in FIGURE_SUFFIXES:
        raise PlanError(
            f"--png {png}: the figure's format comes from its extension; use one of "
            f"{', '.join(FIGURE_SUFFIXES)}"
        )
    try:
        ens = load_ensemble(run / "models" / slug)
    except CheckpointError as e:
        raise PlanError(str(e)) from None
    if not 0 <= model < ens.num_members:
        raise PlanError(f"--model must be in 0..{ens.num_members - 1}, got {model}")
    opts = C.neural_options(cfg.eval, steer=steer)
    res = plan_batch(
        env, member_pnets(ens)[model], np.stack([s, g])[None], jax.random.key(seed), opts
    )
    _draw(env, res, s, g, model, png)
    return res, env, png


def _draw(env, res, s, g, model, png: Path):
    import numpy as np

    from ntq_jax import plotting
    from ntq_jax.types import PlanStatus

    optimum = None
    if env.robot.kind == "point":
        opt = nj.plan(env, np.stack([s, g])[None], "visgraph", padding=0.0)
        if opt.status[0] == PlanStatus.SOLVED:
            optimum = (opt.path(0), float(opt.costs[0]))
    plotting.query_figure(
        env,
        res.path(0),
        bool(res.success[0]),
        float(res.costs[0]),
        f"PNet_{model}",
        s,
        g,
        png,
        optimum=optimum,
    )


def main(argv=None) -> int:
    """Runs the script; an expected error is one ``error:`` line and exit code 2
    (:func:`ntq_jax.experiment.cli.run_cli`)."""
    return run_cli(lambda: _main(argv))


def _model(text: str) -> int:
    """``N`` or ``PNet_<N>`` (as the tables name the members)."""
    m = re.fullmatch(r"(?:PNet_)?(\d+)", text.strip())
    if m is None:
        raise argparse.ArgumentTypeError(f"expected N or PNet_<N> (e.g. 3 or PNet_3), got {text!r}")
    return int(m.group(1))


FIGURE_SUFFIXES = (".png", ".pdf", ".svg", ".jpg", ".jpeg")


def _main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--run", required=True, help="run folder of scripts/train_all.py")
    ap.add_argument("--model", type=_model, required=True, help="ensemble member: N or PNet_<N>")
    ap.add_argument("--start", type=float, nargs="+", required=True, help="start state")
    ap.add_argument("--goal", type=float, nargs="+", required=True, help="goal state")
    ap.add_argument("--env", default=None, help="environment (needed when the run has several)")
    ap.add_argument("--no-steer", action="store_true", help="the variant without steerTo")
    ap.add_argument("--seed", type=seed_arg, default=0, help="dropout seed, 0 .. 2**32-1")
    ap.add_argument("--png", default=None, help="output figure")
    ap.add_argument(
        "--no-compile-cache",
        action="store_true",
        help="do not use JAX's persistent compilation cache",
    )
    args = ap.parse_args(argv)
    if not args.no_compile_cache:
        artifacts.enable_compile_cache()
    from ntq_jax.types import CAUSE_NAMES

    res, env, png = plan_one(
        args.run,
        args.model,
        args.start,
        args.goal,
        env_name=args.env,
        steer=not args.no_steer,
        seed=args.seed,
        png=args.png,
    )
    path = res.path(0)
    print(f"{env.name}, PNet_{args.model}: {CAUSE_NAMES[int(res.cause[0])]}")
    for row in path:
        print("  " + " ".join(f"{v:.4f}" for v in row))
    print(f"cost: {res.costs[0]:.4f}" if res.success[0] else "cost: inf (no collision-free path)")
    print(f"figure: {png}")
    return 0 if res.success[0] else 1


if __name__ == "__main__":
    sys.exit(main())
