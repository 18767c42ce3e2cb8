"""Start-up of a BIT* worker process: the lazy package against the eager imports it replaced.

    python benchmarks/bench_worker_import.py [--reps 7]

Each case is a fresh ``python -c`` process (repeats interleaved, medians printed with
their ratio). ``lazy``: what a worker imports, ``ntq_jax.planners.ompl_worker``, through
the lazy package ``__init__`` modules. ``eager``: the same plus what the package
``__init__`` modules imported before they were lazy (environments, geometry, queries,
presets, every planner), so JAX. Each case also reports whether JAX got loaded.
"""

from __future__ import annotations

import argparse
import subprocess
import sys

from common import interleaved

CASES = {
    "lazy": "import ntq_jax.planners.ompl_worker",
    "eager": (
        "import ntq_jax.planners.ompl_worker, ntq_jax.envs, ntq_jax.geometry, "
        "ntq_jax.presets, ntq_jax.queries, ntq_jax.types, ntq_jax.planners.registry"
    ),
}


def _run(code: str) -> bool:
    out = subprocess.run(
        [sys.executable, "-c", code + "; import sys; print('jax' in sys.modules)"],
        capture_output=True,
        text=True,
        check=True,
    )
    return out.stdout.strip() == "True"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--reps", type=int, default=7, help="processes per case (default 7)")
    args = ap.parse_args()
    loads_jax = {k: _run(c) for k, c in CASES.items()}
    med = interleaved({k: (lambda c=c: _run(c)) for k, c in CASES.items()}, args.reps)
    for k in CASES:
        print(f"{k:6s} {med[k]:.3f} s (median of {args.reps}), loads JAX: {loads_jax[k]}")
    print(f"lazy / eager: {med['lazy'] / med['eager']:.3f}")


if __name__ == "__main__":
    main()
