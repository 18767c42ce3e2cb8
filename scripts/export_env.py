#!/usr/bin/env python
"""Write an environment (preset or JSON map) as JSON, the format users edit and load.

    python scripts/export_env.py point/3 --out point_3.json
    python scripts/export_env.py --list

Expected errors (an unknown preset, a bad map file, an unwritable --out) are one
``error:`` line with the fix, exit code 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ntq_jax.experiment.cli import UsageError, run_cli


def main(argv=None) -> int:
    """The command line; expected errors are one ``error:`` line and exit code 2."""
    return run_cli(lambda: _main(argv))


def _main(argv) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("name", nargs="?", help="preset name (e.g. point/0) or JSON map file")
    ap.add_argument("--out", type=Path, help="output file (default: print to stdout)")
    ap.add_argument("--list", action="store_true", help="list the presets and exit")
    args = ap.parse_args(argv)

    import ntq_jax as nj

    if args.list:
        for name, g in nj.PAPER_GAMMA.items():
            print(f"{name:10s} paper gamma_nt {g:.3f}")
        return 0
    if not args.name:
        raise UsageError("give a preset name or a JSON file (or --list)")
    env = nj.make_env(args.name)
    if args.out:
        env.save_json(args.out)
        print(f"wrote {args.out}")
    else:
        print(json.dumps(env.to_json(), indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
