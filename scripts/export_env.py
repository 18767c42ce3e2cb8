#!/usr/bin/env python
"""Write an environment (preset, Panda problem or JSON map) as JSON, the format users edit
and load; draw a 3-D scene.

    python scripts/export_env.py point/3 --out point_3.json
    python scripts/export_env.py panda/cage/1 --out cage_1.json --png cage_1.png
    python scripts/export_env.py --list

``--png`` draws a 3-D environment's obstacles and its arm at the start and goal of its
query (:func:`ntq_jax.scenes.viewer.draw_scene`).

Expected errors (an unknown preset, a bad map file, an unwritable --out) are one
``error:`` line with the fix, exit code 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ntq_jax.experiment.cli import UsageError, check_writable, run_cli


def main(argv=None) -> int:
    """The command line; expected errors are one ``error:`` line and exit code 2."""
    return run_cli(lambda: _main(argv))


def _main(argv) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument(
        "name",
        nargs="?",
        help="preset name (e.g. point/0), Panda problem (panda/<scene>/<number>) or JSON map file",
    )
    ap.add_argument("--out", type=Path, help="output file (default: print to stdout)")
    ap.add_argument(
        "--png",
        type=Path,
        help="also draw a 3-D scene with its arm at the query's start and goal to this PNG",
    )
    ap.add_argument("--list", action="store_true", help="list the presets and exit")
    args = ap.parse_args(argv)
    for flag, path in (("--out", args.out), ("--png", args.png)):
        if path is not None:
            check_writable(path, flag)

    import ntq_jax as nj

    if args.list:
        from ntq_jax.scenes import mbm

        for name, g in nj.PAPER_GAMMA.items():
            print(f"{name:10s} paper gamma_nt {g:.3f}")
        print(
            f"panda/<scene>/<number>: MotionBenchMaker's Panda problems, scenes "
            f"{', '.join(mbm.SCENES)}; numbers {mbm.NUMBERS[0]}..{mbm.NUMBERS[-1]}"
        )
        return 0
    if not args.name:
        raise UsageError("give a preset name or a JSON file (or --list)")
    env = nj.make_env(args.name)
    if args.png is not None:
        from ntq_jax.geometry import World3D

        if not isinstance(env.world, World3D):
            raise UsageError(
                f"--png draws 3-D scenes; {env.name} is planar (its figures: "
                "ntq_jax.plotting.draw_map)"
            )
        if args.png.suffix.lower() != ".png":
            raise UsageError(f"--png {args.png}: give a file name ending in .png")
    if args.out:
        env.save_json(args.out)
        print(f"wrote {args.out}")
    elif args.png is None:
        print(json.dumps(env.to_json(), indent=1))
    if args.png is not None:
        from ntq_jax.scenes import viewer

        viewer.save(viewer.draw_scene(env), args.png)
        print(f"wrote {args.png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
