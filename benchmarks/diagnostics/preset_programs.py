#!/usr/bin/env python
"""Fingerprints of the presets' compiled kernels: the lowered StableHLO of every batched entry point.

    PYTHONPATH=/tmp/base python benchmarks/diagnostics/preset_programs.py > base.json
    PYTHONPATH=.         python benchmarks/diagnostics/preset_programs.py > head.json
    python -c "import json; a, b = (json.load(open(f)) for f in ('base.json', 'head.json')); \\
               print([k for k in a if a[k] != b[k]] or 'identical')"

For ``point/0``, ``point/3``, ``rigid/3``, ``nlink/2``, ``nlink/6`` at padding 0 and at
the preset's padding: ``is_valid_batch`` and ``steer_to_batch`` (discretised and
certified) lowered for 4,096 states, as a sha256 prefix of the program text. Equal
fingerprints on two checkouts mean the same programs: the same answers and speed.
"""

import argparse
import hashlib
import json

import jax.numpy as jnp

import ntq_jax as nj
from ntq_jax.robots import batch


def main(argv=None) -> int:
    argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    ).parse_args(argv)
    out = {}
    for name in ("point/0", "point/3", "rigid/3", "nlink/2", "nlink/6"):
        e = nj.make_env(name)
        x = jnp.zeros((4096, e.dim), jnp.float32)
        for pad in (0.0, e.padding):
            out[f"{name} is_valid pad {pad:g}"] = batch.is_valid_batch.lower(
                e.robot, e.world, x, pad
            ).as_text()
            for check in ("discretized", "certified"):
                out[f"{name} steer {check} pad {pad:g}"] = batch._steer_to_batch.lower(
                    e.robot, e.world, x, x, pad, check
                ).as_text()
    print(
        json.dumps(
            {k: hashlib.sha256(v.encode()).hexdigest()[:16] for k, v in out.items()}, indent=1
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
