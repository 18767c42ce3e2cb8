#!/usr/bin/env python
"""Presets before/after: ``bench_steer.py`` on two checkouts, alternating, medians side by side.

    git archive <base-commit> | tar -x -C /tmp/base      # the previous commit, untouched
    python benchmarks/diagnostics/ab_presets.py --base /tmp/base --rounds 3 -- --quick --only certified

Each round runs ``benchmarks/bench_steer.py <args>`` once with ``ntq_jax`` imported
from ``--base`` and once from ``--head`` (default: this checkout), alternating
the order, each in a fresh process; the table gives, per row of bench_steer's
output that has a rate (``per_second``), the median over rounds for each side and
the ratio head / base (> 1: the head is faster). Both sides run the same
benchmark script (this checkout's), so only the package differs.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent.parent  # benchmarks/, where bench_steer.py is


def run(src: Path, args: list[str]) -> list[dict]:
    with tempfile.NamedTemporaryFile(suffix=".json") as f:
        env = dict(os.environ, PYTHONPATH=str(src))
        subprocess.run(
            [sys.executable, str(HERE / "bench_steer.py"), *args, "--json", f.name],
            check=True,
            env=env,
            stdout=subprocess.DEVNULL,
        )
        return json.loads(Path(f.name).read_text())


def rows_of(out) -> list[dict]:
    return out["rows"] if isinstance(out, dict) and "rows" in out else out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--base", type=Path, required=True)
    ap.add_argument("--head", type=Path, default=HERE.parent)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--json", type=Path)
    ap.add_argument("bench_args", nargs="*", help="arguments of bench_steer.py (after --)")
    args = ap.parse_args(argv)
    rates: dict[str, dict[str, list[float]]] = {"base": {}, "head": {}}
    load = [os.getloadavg()]
    for r in range(args.rounds):
        sides = ("base", "head") if r % 2 == 0 else ("head", "base")
        for side in sides:
            for row in rows_of(run(getattr(args, side), args.bench_args)):
                if isinstance(row, dict) and "per_second" in row:
                    rates[side].setdefault(row["name"], []).append(float(row["per_second"]))
        print(f"round {r + 1}/{args.rounds} done", file=sys.stderr, flush=True)
    load.append(os.getloadavg())
    table = []
    print(f"load average {load[0][0]:.2f} -> {load[1][0]:.2f}")
    print("| row | base (median /s) | head (median /s) | head / base |")
    print("|---|---|---|---|")
    for name, base in rates["base"].items():
        head = rates["head"].get(name)
        if not head:
            continue
        b, h = float(np.median(base)), float(np.median(head))
        table.append({"name": name, "base": b, "head": h, "ratio": h / b, "rounds": len(base)})
        print(f"| {name} | {b:,.0f} | {h:,.0f} | {h / b:.2f} |")
    if args.json:
        args.json.write_text(json.dumps({"load": load, "rows": table}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
