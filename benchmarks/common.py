"""What the benchmarks share: interleaved timing, the machine and its load, small number helpers.

A benchmark script imports it as ``from common import ...`` (the script's own
folder is first on ``sys.path`` when it runs as ``python benchmarks/<script>.py``).
"""

from __future__ import annotations

import datetime
import json
import math
import os
import resource
import subprocess
import sys
import time
from pathlib import Path


def interleaved(cases: dict, reps: int) -> dict:
    """Median seconds of each ``fn`` in ``cases`` (name -> fn), repeats interleaved round-robin.

    Also records in ``interleaved.cores[name]`` the mean number of cores used
    (process CPU time / wall time): on a shared machine a figure measured with
    ~1 core is not one measured with 2.
    """
    import jax
    import numpy as np

    for fn in cases.values():  # warm-up: compile, first-touch
        jax.block_until_ready(fn())
    times = {k: [] for k in cases}
    cpu = {k: 0.0 for k in cases}
    for _ in range(reps):
        for k, fn in cases.items():
            c0, t0 = time.process_time(), time.perf_counter()
            jax.block_until_ready(fn())
            times[k].append(time.perf_counter() - t0)
            cpu[k] += time.process_time() - c0
    interleaved.cores = {k: cpu[k] / sum(times[k]) for k in cases}
    return {k: float(np.median(v)) for k, v in times.items()}


def git_revision() -> dict:
    import ntq_jax

    pkg = Path(ntq_jax.__file__).resolve().parent

    def run(*a):
        try:
            return subprocess.run(
                ["git", "-C", str(pkg), *a], capture_output=True, text=True, timeout=30
            ).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            return ""

    return {
        "git_revision": run("rev-parse", "--short", "HEAD") or "unknown",
        "git_dirty": bool(run("status", "--porcelain", "--", ".")),
        "package_path": str(pkg),
    }


def machine() -> dict:
    import jax
    import numpy as np

    return {
        "cpu_count": os.cpu_count(),
        "python": sys.version.split()[0],
        "jax": jax.__version__,
        "numpy": np.__version__,
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        **git_revision(),
    }


def loadavg() -> list[float]:
    return [round(x, 2) for x in os.getloadavg()]


class LoadSampler:
    """Samples the 1-minute load average every ``every`` seconds in a thread (``with`` block)."""

    def __init__(self, every: float = 15.0):
        import threading

        self.every, self.samples = every, []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self):
        while True:
            self.samples.append(os.getloadavg()[0])
            if self._stop.wait(self.every):
                return

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()

    def summary(self) -> dict:
        xs = self.samples
        return (
            {
                "mean": round(sum(xs) / len(xs), 2),
                "max": round(max(xs), 2),
                "n": len(xs),
                "every_s": self.every,
            }
            if xs
            else {}
        )


def children_cpu() -> float:
    """User + system CPU seconds of this process's exited, waited-for children."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def finite_or_none(x) -> float | None:
    x = float(x)
    return round(x, 6) if math.isfinite(x) else None


def percentile(xs, p):
    import numpy as np

    return float(np.percentile(np.asarray(xs, np.float64), p)) if len(xs) else float("nan")


def load_json(path: Path) -> dict | None:
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as e:
        print(f"  {path}: unreadable ({e}); ignored", flush=True)
        return None
