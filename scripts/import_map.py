#!/usr/bin/env python
"""Convert a ROS map_server map (YAML + PGM/PNG) or a MovingAI .map into our map JSON.

    python scripts/import_map.py office.yaml --padding 0.1 --out office.json
    python scripts/import_map.py maze512-8-0.map --scale 0.5 \\
        --robot '{"kind": "rigid_body", "length": 1.2, "width": 0.4}' --out maze.json
    python scripts/import_map.py office.yaml --unknown free           # print to stdout

The occupied cells become boxes by an exact rectangle cover
(:func:`ntq_jax.grid_maps.rectangle_cover`), the grid's extent the bounds; the
JSON loads anywhere a map file is accepted and gives the same environment
(same content hash) as the grid file itself with the same robot and padding.
``--robot`` is a kind (``point``, ``rigid_body``, ``nlink``: default parameters)
or a robot JSON object. Expected errors (a malformed map file, a bad option, an
unwritable --out) are one ``error:`` line, exit code 2.
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


def _robot(text: str) -> dict:
    if text.lstrip().startswith("{"):
        try:
            robot = json.loads(text)
        except json.JSONDecodeError as e:
            raise UsageError(f"--robot is not valid JSON: {e}") from None
        if not isinstance(robot, dict):
            raise UsageError("--robot must be a kind or a JSON object")
        return robot
    return {"kind": text}


def _main(argv) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("grid", help="a ROS map .yaml/.yml or a MovingAI .map file")
    ap.add_argument("--robot", default="point", help="robot kind or robot JSON (default: point)")
    ap.add_argument(
        "--padding", type=float, default=0.0, help="data-generation padding (default 0)"
    )
    ap.add_argument("--name", help="map name (default: the file's stem)")
    ap.add_argument(
        "--unknown",
        choices=("occupied", "free"),
        default="occupied",
        help="ROS maps: what unknown cells become (default occupied)",
    )
    ap.add_argument("--scale", type=float, help="MovingAI maps: world units per cell (default 1)")
    ap.add_argument("--out", type=Path, help="output JSON (default: print to stdout)")
    args = ap.parse_args(argv)

    from ntq_jax.envs import Env

    if args.out:
        check_writable(args.out, "--out")  # a folder or an unwritable place: before the work
    env = Env.from_grid(
        args.grid, _robot(args.robot), args.padding, args.name, args.unknown, args.scale
    )
    h, w = env.grid.shape
    summary = (
        f"{args.grid}: {w} x {h} cells of {env.grid.resolution:g}, "
        f"{int(env.grid.occupied.sum())} occupied -> {env.world.num_boxes} boxes"
    )
    if args.out:
        env.save_json(args.out)
        print(f"{summary}; wrote {args.out}")
    else:
        print(summary, file=sys.stderr)
        print(json.dumps(env.to_json()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
