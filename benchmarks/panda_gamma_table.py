#!/usr/bin/env python
"""Pool the Panda gamma_nt series and write its table: ``results/panda_gamma/README.md``.

For each MotionBenchMaker scene, the units in ``results/panda_gamma/series/<scene>/``
are pooled again (:func:`ntq_jax.experiment.gamma_units.pool`, population 100, as
``measure_gamma.py --pool <units> --population 100`` does, so the scene's mean counts the
problems not yet measured) into ``series/<scene>.json``; then the
README's table (from its header row ``| scene | problems measured |`` to the next blank
line) and the count of units in BENCHMARKS.md's summary row ("N of the 700 units
committed") are rewritten from those files. Run it after a batch of units lands:

    python benchmarks/panda_gamma_table.py

Refuses (exit code 1, one line) a pool whose units share a seed across problems (one
query stream in several worlds: see the README's discarded first series).
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

from ntq_jax import artifacts
from ntq_jax.experiment import gamma_units
from ntq_jax.scenes.mbm import SCENES

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results" / "panda_gamma"
HEADER = "| scene | problems measured |"
COLUMNS = (
    "| scene | problems measured | queries | gamma_nt of the problems measured | "
    "95 % interval (their queries) | spread between problems | "
    "the scene's mean, 95 % interval (its 100 problems) |"
)


def pool_scene(scene: str) -> dict | None:
    """``series/<scene>.json`` pooled again from the scene's units (None without units)."""
    paths = sorted((RESULTS / "series" / scene).glob("problem_*.json"))
    if not paths:
        return None
    pooled = gamma_units.pool([json.loads(p.read_text()) for p in paths], population=100)
    if pooled["worlds"]["shared_queries"]:
        raise SystemExit(f"{scene}: units of several problems share a seed; measure them again")
    artifacts.write_json(RESULTS / "series" / f"{scene}.json", pooled)
    return pooled


def row(scene: str, d: dict) -> str:
    lo, hi = d["ci95"]
    w = d["worlds"]
    spread = "-" if w["spread"] != w["spread"] else f"{w['spread']:.3f}"
    mean = "-" if w["ci95"] is None else "[{:.4f}, {:.4f}]".format(*w["ci95"])
    return (
        f"| {scene} | {d['units']} | {d['queries']:,} | {d['gamma']:.4f} | "
        f"[{lo:.4f}, {hi:.4f}] | {spread} | {mean} |"
    )


def main() -> int:
    rows, total = [COLUMNS, "|---|---|---|---|---|---|---|"], 0
    for scene in SCENES:
        pooled = pool_scene(scene)
        if pooled is not None:
            rows.append(row(scene, pooled))
            total += pooled["units"]
    readme = RESULTS / "README.md"
    text = readme.read_text()
    i = text.index(HEADER)
    j = text.find("\n\n", i)
    readme.write_text(text[:i] + "\n".join(rows) + ("\n" if j < 0 else text[j:]))
    bench = ROOT / "BENCHMARKS.md"
    text = bench.read_text()
    bench.write_text(
        re.sub(r"\d+ of the 700 units committed", f"{total} of the 700 units committed", text)
    )
    print("\n".join(rows))
    print(f"{total} of the 700 units")
    return 0


if __name__ == "__main__":
    sys.exit(main())
