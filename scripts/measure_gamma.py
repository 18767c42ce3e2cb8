#!/usr/bin/env python
"""Measure gamma_nt (the non-trivial fraction of uniform queries) of an environment.

Streams N uniform queries in fixed-size chunks (memory stays flat for 1e9 and
beyond: it is that of one chunk, printed with the time estimate), shows
progress, and prints the estimate, its 95% Wilson interval, elapsed seconds,
throughput and peak memory.

    python scripts/measure_gamma.py --env point/3 --queries 100000000
    python scripts/measure_gamma.py --env my_map.json --queries 1e6 --padding 0.8 --json out.json
    taskset -c 0 python scripts/measure_gamma.py --env panda/cage/1 --queries 1e5 \
        --json results/panda_gamma/cage.json --skip-existing

The default padding is 0, the evaluation geometry on which the paper reports
gamma_nt; ``--padding`` measures another geometry (e.g. the data-generation one).

A 3-D scene (``panda/<scene>/<number>``, a 3-D JSON) is measured over the world of
that one problem: MotionBenchMaker's problems of a scene place it at different poses
around the robot and rearrange its small objects, so their gamma_nt differ (problems
1-10 of bookshelf_tall: 0.08 to 0.25; see results/panda_gamma/README.md). Its motions are checked
at the arm's resolution (1/32 rad: ~170 states on an
average free 7-D motion), so it runs at thousands of queries per second, not millions,
after the arm's shared checks are compiled (``is_valid`` and the discretised
``steer_to``, the programs data generation and planning use: seconds each; the
persistent compilation cache keeps them for the next run unless ``--no-compile-cache``).

``--skip-existing`` makes a series of runs resumable: when ``--json`` already holds
a result of the same environment, queries, padding, seed and chunk, it is printed
and nothing is measured.

A measurement too long for one sitting (10^8 queries of a Panda scene: hours of a core)
runs as units with the same padding and chunk, each its own ``--json`` (resumable with
``--skip-existing``): one environment with different seeds (independent uniform
samples of it), or different environments, e.g. the 100 problems of a scene (each
problem places the scene differently; the mean over their worlds is the scene's
gamma_nt). ``--pool`` adds their counts up into one estimate over all their queries,
with its Wilson interval; over several envs it also gives their family's mean
(``worlds`` in the JSON: the mean over the envs measured, with an interval that adds
the spread between worlds, ``ntq_jax.world_mean``) for a family of ``--population``
worlds (100 for a Panda scene's problems; default unbounded):

    for n in $(seq 1 100); do
      python scripts/measure_gamma.py --env panda/cage/$n --queries 1e6 \
          --json results/panda_gamma/series/cage/problem_$n.json --skip-existing --no-progress
    done
    python scripts/measure_gamma.py --pool results/panda_gamma/series/cage/problem_*.json \
        --population 100 --json results/panda_gamma/series/cage.json

After the first chunks the estimated time of the streaming is printed; a run that would take
longer than ``--max-hours`` (default 24) stops there with an error. Ctrl-C
prints the estimate over the queries counted so far (with its interval) and
exits with code 130; ``--json`` is then not written. Bad arguments, an unknown
environment, an unwritable ``--json`` path (checked before any work) and a map
without free space end in one ``error:`` line and exit code 2.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

from ntq_jax.experiment.cli import UsageError, check_writable, run_cli, seed_arg

MAX_QUERIES = 10**15  # ~80 days at the fastest measured rate (1.5e8 queries/s, point robot)
INTERRUPTED = 130  # the shell's exit code for a process ended by SIGINT
#: The default chunk of a 3-D arm (``ntq_jax.gamma.default_chunk`` is 2**15): at a few
#: thousand queries per second, 4096 candidates take about a second, so the bar moves
#: steadily, at the rate of 2**15 (panda/box/1 on one core: 2,860 vs 2,430 queries/s).
ARM3D_CHUNK = 4096


class ScriptError(UsageError):
    """An expected failure of this script: reported as one ``error:`` line, exit code 2."""


def _count(text: str, maximum: int | None = None) -> int:
    """A whole number >= 1 (``1e9`` accepted), at most ``maximum``."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (math.isfinite(v) and v >= 1 and v == int(v)):
        raise argparse.ArgumentTypeError(f"must be a whole number >= 1, got {text!r}")
    if maximum is not None and v > maximum:
        raise argparse.ArgumentTypeError(f"must be at most {maximum:.0e}, got {text!r}")
    return int(v)


def _queries(text: str) -> int:
    return _count(text, MAX_QUERIES)


def _chunk(text: str) -> int:
    from ntq_jax.gamma import MAX_CHUNK

    return _count(text, MAX_CHUNK)


def _padding(text: str) -> float:
    """A finite number >= 0."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (math.isfinite(v) and v >= 0):
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {text!r}")
    return v


def _hours(text: str) -> float:
    """A number of hours > 0 (``inf`` allowed: no limit)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not v > 0:  # also refuses NaN
        raise argparse.ArgumentTypeError(f"must be a number of hours > 0 (or inf), got {text!r}")
    return v


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 2 * 3600:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:,.1f} h"


class _Eta:
    """Progress callback: the tqdm bar, plus one time estimate printed after ~0.25 s of streaming.

    The rate is measured from the end of the first chunk (which includes the
    compilation) on; if the estimate exceeds ``max_hours`` it raises ScriptError,
    which stops :func:`ntq_jax.gamma.gamma_nt` before any more work. The estimate
    is of the streaming only: the last chunk's prefix is counted by a second program,
    compiled at the end (about a minute for a 3-D arm the first time).
    """

    def __init__(self, bar, total: int, max_hours: float):
        self.bar, self.total, self.max_hours = bar, total, max_hours
        self.start = time.monotonic()
        self.first: tuple[float, int] | None = None
        self.last: tuple[float, int] | None = None
        self.reported = False

    def streaming(self) -> tuple[float | None, float | None]:
        """``(seconds to the first chunk counted (compilation included), queries per second
        after it)``; None where not measured (an estimate read off the first chunk)."""
        if self.first is None:
            return None, None
        ahead = self.first[0] - self.start
        if self.last is None or self.last[0] <= self.first[0]:
            return ahead, None
        return ahead, (self.last[1] - self.first[1]) / (self.last[0] - self.first[0])

    def __call__(self, done: int) -> None:
        self.bar.update(done - self.bar.n)
        now = time.monotonic()
        if self.first is None:
            self.first = (now, done)
            return
        if done < self.total:  # the final call follows the last chunk's prefix (compiled apart)
            self.last = (now, done)
        t0, d0 = self.first
        if self.reported or done >= self.total or now - t0 < 0.25 or done <= d0:
            return
        self.reported = True
        rate = (done - d0) / (now - t0)
        eta = (self.total - done) / rate
        msg = (
            f"{self.total:,} queries at {rate:,.0f} queries/s: about {_duration(eta)} left; "
            f"memory {_peak_gib():.2f} GiB, flat from here (fixed-size chunks)"
        )
        if eta > self.max_hours * 3600:
            raise ScriptError(
                f"{msg}, more than --max-hours {self.max_hours:g}: ask for fewer "
                "--queries, or raise --max-hours"
            )
        self.bar.write(msg, file=sys.stderr)


def _cpu_seconds() -> float:
    """This process's user + system CPU time (all its threads), in seconds."""
    t = os.times()
    return t.user + t.system


def _peak_gib() -> float:
    """This process's peak resident memory in GiB (Linux and macOS units)."""
    import resource

    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / (2**30 if sys.platform == "darwin" else 2**20)


def _existing(
    path: Path, env: str, queries: int, padding: float, seed: int, chunk: int | None
) -> dict | None:
    """The result in ``path`` if it is this measurement (else None: measure it)."""
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    same = (
        isinstance(data, dict)
        and data.get("env") == env
        and data.get("queries") == queries
        and data.get("padding") == padding
        and data.get("seed") == seed
        and data.get("chunk") == chunk
    )
    return data if same else None


def _report_json(d: dict) -> None:
    print(
        f"env {d['env']}  padding {d['padding']:g}  queries {d['queries']:,}  "
        f"non-trivial {d['non_trivial']:,}"
    )
    print(f"gamma_nt = {d['gamma']:.6f}  95% CI [{d['ci95'][0]:.6f}, {d['ci95'][1]:.6f}]")
    print(f"{d['seconds']:.2f} s  {d['queries_per_second']:,.0f} queries/s (when measured)")


def _report_worlds(w: dict) -> None:
    of = "an unbounded family" if w["population"] is None else f"{w['population']}"
    ci = (
        "no interval (one world)"
        if w["ci95"] is None
        else (f"95% CI [{w['ci95'][0]:.6f}, {w['ci95'][1]:.6f}]")
    )
    print(
        f"mean over {w['measured']} of {of} worlds = {w['mean']:.6f}  {ci}  "
        f"(spread between worlds {w['spread']:.4f})"
    )


def _report(env, padding: float, est, file=None) -> None:
    lo, hi = est.ci95
    print(
        f"env {env.name}  padding {padding:g}  queries {est.queries:,}  "
        f"non-trivial {est.non_trivial:,}",
        file=file,
    )
    print(f"gamma_nt = {est.gamma:.6f}  95% CI [{lo:.6f}, {hi:.6f}]", file=file)
    print(
        f"{est.seconds:.2f} s  {est.queries_per_second:,.0f} queries/s  "
        f"({est.candidates_per_second:,.0f} raw candidates/s)  peak memory "
        f"{_peak_gib():.2f} GiB",
        file=file,
    )


def _parser() -> argparse.ArgumentParser:
    """The command line's options."""
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument(
        "--env",
        default="point/0",
        help="preset name (point/0..3, rigid/0..3, "
        "nlink/2|4|6), a Panda problem (panda/<scene>/<number>, e.g. panda/cage/1) "
        "or a JSON map file (default: point/0)",
    )
    ap.add_argument(
        "--queries",
        type=_queries,
        default=10**7,
        help=f"uniform valid queries to examine; accepts 1e9 (default: 1e7, at most "
        f"{MAX_QUERIES:.0e})",
    )
    ap.add_argument(
        "--padding",
        type=_padding,
        default=0.0,
        help="clearance of the geometry (default 0: the evaluation geometry)",
    )
    ap.add_argument("--seed", type=seed_arg, default=0, help="PRNG seed, 0 .. 2**32-1")
    ap.add_argument(
        "--chunk",
        type=_chunk,
        default=None,
        help="candidate queries per compiled chunk (default: 4M point, 256k point on a "
        "map of more than 64 boxes, 4096 a 3-D arm, 32k others); memory grows with "
        "it, not with --queries",
    )
    ap.add_argument(
        "--max-hours",
        type=_hours,
        default=24.0,
        help="stop at once if the time estimate exceeds this (default 24; inf: no limit)",
    )
    ap.add_argument("--json", type=Path, default=None, help="also write the result as JSON")
    ap.add_argument(
        "--skip-existing",
        action="store_true",
        help="if --json already holds this measurement (same env, queries, padding, "
        "seed, chunk), print it and measure nothing",
    )
    ap.add_argument(
        "--pool",
        type=Path,
        nargs="+",
        default=None,
        metavar="JSON",
        help="measure nothing: add up the counts of these --json results (the same "
        "padding and chunk; one env with different seeds, or different envs) into one "
        "estimate, printed and written to --json",
    )
    ap.add_argument(
        "--population",
        type=_count,
        default=None,
        metavar="N",
        help="with --pool: how many worlds the family the pooled envs are drawn from "
        "has (e.g. 100, a Panda scene's problems), for the interval of the family's mean; "
        "default: an unbounded family (a wider interval)",
    )
    ap.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    ap.add_argument(
        "--no-compile-cache",
        action="store_true",
        help="do not use JAX's persistent compilation cache (~/.cache/ntq_jax/jax; "
        "a 3-D arm's two programs take about a minute to compile)",
    )
    return ap


#: What the units of a pooled measurement must share (``--pool``).
POOL_KEYS = ("padding", "chunk", "resolution", "check")


def _pool(paths: list[Path], population: int | None = None) -> dict:
    """One estimate over the queries of the unit results in ``paths`` (see ``--pool``).

    With several envs, ``worlds`` adds the mean over their worlds (each env's units
    summed into one world) with the interval of a family of ``population`` worlds
    (:func:`ntq_jax.world_mean.world_mean`; None: an unbounded family).
    """
    from ntq_jax.stats import wilson_interval, world_mean

    units = []
    for path in paths:
        try:
            d = json.loads(path.read_text())
        except (OSError, ValueError) as e:
            raise ScriptError(f"--pool: cannot read {path}: {e}") from None
        if not isinstance(d, dict) or not {"queries", "non_trivial", "seed", *POOL_KEYS} <= set(d):
            raise ScriptError(f"--pool: {path} is not a result of measure_gamma.py --json")
        units.append(d)
    for key in POOL_KEYS:
        values = {json.dumps(u[key]) for u in units}
        if len(values) > 1:
            raise ScriptError(
                f"--pool: the units differ in {key} ({', '.join(sorted(values))}): pool "
                "measurements of one geometry"
            )
    seeds = [u["seed"] for u in units]
    envs = [u["env"] for u in units]
    if len(set(zip(envs, seeds))) < len(units):
        raise ScriptError(
            "--pool: two units have the same env and seed (the same queries): give each "
            "unit of one env its own --seed"
        )
    queries = sum(u["queries"] for u in units)
    blocked = sum(u["non_trivial"] for u in units)
    lo, hi = wilson_interval(blocked, queries)
    out = {"env": envs[0] if len(set(envs)) == 1 else sorted(set(envs), key=envs.index)}
    out.update({key: units[0][key] for key in POOL_KEYS})
    out.update(
        queries=queries,
        non_trivial=blocked,
        gamma=blocked / queries,
        ci95=[lo, hi],
        candidates=sum(u.get("candidates", 0) for u in units),
        units=len(units),
        seeds=sorted(seeds),
        cpu_seconds=sum(u.get("cpu_seconds") or 0.0 for u in units),
        seconds=sum(u.get("seconds") or 0.0 for u in units),
    )
    out["queries_per_second"] = queries / out["seconds"] if out["seconds"] else 0.0
    if "version" in units[0]:
        out["version"] = units[0]["version"]
    if len(set(envs)) > 1:
        out["world"] = (
            "the worlds of these environments, the same number of queries from each when "
            "their units are alike: gamma_nt is then their mean (the interval is "
            "conservative for that mean of fixed worlds; see worlds for the family's)"
        )
    elif "world" in units[0]:
        out["world"] = units[0]["world"]
    if len(set(envs)) > 1 or population is not None:
        names = sorted(set(envs), key=envs.index)
        if population is not None and population < len(names):
            raise ScriptError(
                f"--population {population} is smaller than the {len(names)} envs pooled"
            )
        hits = [sum(u["non_trivial"] for u in units if u["env"] == e) for e in names]
        counts = [sum(u["queries"] for u in units if u["env"] == e) for e in names]
        wm = world_mean(hits, counts, population=population)
        out["worlds"] = {
            "measured": wm.worlds,
            "population": wm.population,
            "mean": wm.mean,
            "spread": wm.spread,
            "ci95": None if wm.ci95 is None else list(wm.ci95),
            "df": wm.df if math.isfinite(wm.df) else None,
            "about": "the mean of gamma_nt over a family of worlds of which these were "
            "measured; its interval adds the spread between worlds (shrinking to the "
            "queries' alone as every world of the population is measured), "
            "ntq_jax.world_mean",
        }
    return out


def _run(argv) -> int:
    args = _parser().parse_args(argv)
    if args.pool is not None:
        if args.json is None:
            raise ScriptError("--pool needs --json (the file the pooled estimate is written to)")
        check_writable(args.json, "--json")
        from ntq_jax import artifacts

        pooled = _pool(args.pool, args.population)
        _report_json(pooled)
        print(
            f"pooled from {pooled['units']} units (seeds {pooled['seeds'][0]}..{pooled['seeds'][-1]})"
        )
        if "worlds" in pooled:
            _report_worlds(pooled["worlds"])
        artifacts.write_json(args.json, pooled)
        return 0
    if args.population is not None:
        raise ScriptError("--population needs --pool (it describes the pooled envs' family)")
    if args.skip_existing and args.json is None:
        raise ScriptError("--skip-existing needs --json (the file a finished run wrote)")
    if args.json is not None:
        check_writable(args.json, "--json")

    import jax
    from tqdm import tqdm

    import ntq_jax as nj
    from ntq_jax import artifacts
    from ntq_jax.gamma import default_chunk
    from ntq_jax.geometry import World3D

    if not args.no_compile_cache:
        artifacts.enable_compile_cache()
    env = nj.make_env(args.env)
    three_d = isinstance(env.world, World3D)
    chunk = (
        args.chunk
        if args.chunk is not None
        else (ARM3D_CHUNK if three_d else default_chunk(env.robot, env.world))
    )
    if args.skip_existing:
        done = _existing(args.json, env.name, args.queries, args.padding, args.seed, chunk)
        if done is not None:
            print(f"{args.json} already holds this measurement; not measured again")
            _report_json(done)
            return 0
    bar = tqdm(
        total=args.queries,
        unit="q",
        unit_scale=True,
        disable=args.no_progress,
        desc=f"gamma_nt {env.name}",
        file=sys.stderr,
    )
    eta = _Eta(bar, args.queries, args.max_hours)
    cpu0 = _cpu_seconds()
    try:
        est = env.gamma_nt(
            jax.random.key(args.seed), args.queries, padding=args.padding, chunk=chunk, progress=eta
        )
    except KeyboardInterrupt as e:
        bar.close()
        partial = getattr(e, "estimate", None)
        if partial is None:
            print("interrupted before the first chunk was counted: no estimate", file=sys.stderr)
        else:
            print(
                f"interrupted after {partial.queries:,} of {args.queries:,} queries; the "
                "estimate so far:"
            )
            _report(env, args.padding, partial)
        if args.json is not None:
            print(f"{args.json} not written (interrupted)", file=sys.stderr)
        return INTERRUPTED
    finally:
        bar.close()
    _report(env, args.padding, est)
    cpu = _cpu_seconds() - cpu0
    ahead, rate = eta.streaming()
    if rate is not None:
        print(
            f"streaming: {rate:,.0f} queries/s after the first chunk ({ahead:.1f} s to it, "
            "compilation included)"
        )
    print(
        f"cpu time {cpu:.1f} s, {est.queries / max(cpu, 1e-9):,.0f} queries per cpu-second "
        "(compilation included; on a shared core the wall-clock rate is lower)"
    )
    if args.json:
        artifacts.write_json(
            args.json, _result_json(env, args, est, chunk, cpu, ahead, rate, three_d)
        )
    return 0


def _result_json(env, args, est, chunk: int, cpu: float, ahead, rate, three_d: bool) -> dict:
    """What ``--json`` writes: the estimate, its interval, rates and the settings."""
    import ntq_jax as nj

    lo, hi = est.ci95
    resolution = getattr(env.robot, "resolution", None)
    out = {
        "env": env.name,
        "padding": args.padding,
        "seed": args.seed,
        "queries": est.queries,
        "non_trivial": est.non_trivial,
        "gamma": est.gamma,
        "ci95": [lo, hi],
        "seconds": est.seconds,
        "queries_per_second": est.queries_per_second,
        "candidates": est.candidates,
        "candidates_per_second": est.candidates_per_second,
        "cpu_seconds": cpu,
        "first_chunk_seconds": ahead,
        "streaming_queries_per_second": rate,
        "chunk": chunk,
        "resolution": resolution,
        "check": "exact" if resolution is None else "discretized",
        "cpus": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
        "version": nj.__version__,
    }
    if three_d:
        out["world"] = (
            "the world of this one problem (the problems of a scene place it "
            "differently, and their gamma_nt differ)"
        )
    return out


def main(argv=None) -> int:
    """Runs the script through :func:`ntq_jax.experiment.cli.run_cli`: an expected error (a bad option, an
    unknown environment or bad map, too little free space, a path that cannot be written) is
    one ``error:`` line on stderr and exit code 2; Ctrl-C exits with code 130 without a
    traceback (during the estimate, after printing the estimate so far)."""
    from ntq_jax.queries import FreeSpaceTooSmall

    return run_cli(lambda: _run(argv), extra=(FreeSpaceTooSmall,))


if __name__ == "__main__":
    sys.exit(main())
