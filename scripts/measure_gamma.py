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
1-10 of bookshelf_tall: 0.08 to 0.25; see results/panda_gamma/README.md). Its motions
are checked at the arm's resolution (1/32 rad: ~170 states on an average free 7-D
motion), so it runs at thousands of queries per second, not millions,
after the arm's shared checks are compiled (``is_valid`` and the discretised
``steer_to``, the programs data generation and planning use: about 10 s for both, 12 s
to the first chunk of panda/cage/1; the persistent compilation cache keeps them for the
next run, 3 s to the first chunk, unless ``--no-compile-cache``).

``--skip-existing`` makes a series of runs resumable: when ``--json`` already holds
a result of the same environment, queries, padding, seed and chunk, it is printed
and nothing is measured.

A Panda scene, ``--env panda/<scene>``, is its 100 problems' worlds (each places the
scene differently; the mean over them is the scene's gamma_nt). ``--queries`` is split
into one unit per problem (1e8: 1e6 on each, hours of a core). Each unit is written as
it finishes, in the folder beside ``--json`` (``series/cage.json`` has its units in
``series/cage/problem_<n>.json``), and skipped when already there, so the run stops and
resumes at any unit. Problem ``n`` is measured with seed ``100 s + n - 1`` (``s``:
``--seed``), so the problems' queries are independent. After each unit ``--json``
pools the units present: the scene's mean and its interval, which counts the problems
not yet measured. ``--problems 51-100`` measures some of the units only, e.g. on a
second core:

    python scripts/measure_gamma.py --env panda/cage --queries 1e8 \
        --json results/panda_gamma/series/cage.json

Any measurement too long for one sitting runs as units with the same padding and chunk,
each its own ``--json`` (resumable with ``--skip-existing``): one environment with
different seeds (independent uniform samples of it), or different environments.
``--pool`` adds their counts up into one estimate over all their queries, with its
Wilson interval; over several envs it also gives their family's mean (``worlds`` in the
JSON, ``ntq_jax.world_mean``) for a family of ``--population`` worlds (default: an
unbounded family, the wider interval). The scene's units above, pooled again:

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


def _problems(text: str) -> list[int]:
    """Problem numbers: ``A-B`` ranges and single numbers, comma-separated, in order."""
    out: list[int] = []
    seen: set[int] = set()
    for part in text.split(","):
        lo, sep, hi = part.strip().partition("-")
        try:
            a, b = int(lo), int(hi) if sep else int(lo)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"not a list of problem numbers: {text!r} (e.g. 1-50 or 3,7,9)"
            ) from None
        if a > b:
            raise argparse.ArgumentTypeError(f"empty range {part.strip()!r} in {text!r}")
        if b - a > 10**6:
            raise argparse.ArgumentTypeError(f"range {part.strip()!r} too long")
        out.extend(k for k in range(a, b + 1) if k not in seen)
        seen.update(range(a, b + 1))
    return out


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
    compiled at the end (for fused chunks; a 3-D arm's prefix reuses its shared checks).
    In a series of units (a scene's problems) the bar counts from ``offset`` (the units
    measured before) and the estimate also covers ``after`` queries (the units to come).
    """

    def __init__(self, bar, total: int, max_hours: float, offset: int = 0, after: int = 0):
        self.bar, self.total, self.max_hours = bar, total, max_hours
        self.offset, self.after = offset, after
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
        self.bar.update(self.offset + done - self.bar.n)
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
        eta = (self.total - done + self.after) / rate
        msg = (
            f"{self.total + self.after:,} queries at {rate:,.0f} queries/s: "
            f"about {_duration(eta)} left; "
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
    spread = "" if w["spread"] != w["spread"] else f"  (spread between worlds {w['spread']:.4f})"
    print(f"mean over {w['measured']} of {of} worlds = {w['mean']:.6f}  {ci}{spread}")


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
    ap.add_argument(
        "--problems",
        type=_problems,
        default=None,
        metavar="LIST",
        help="with --env panda/<scene>: measure only these problems' units, e.g. 1-50 "
        "(another process may take 51-100) or 3,7,9; default: all 100",
    )
    ap.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    ap.add_argument(
        "--no-compile-cache",
        action="store_true",
        help="do not use JAX's persistent compilation cache (~/.cache/ntq_jax/jax; "
        "a 3-D arm's two shared checks take about 10 s to compile)",
    )
    return ap


def _read_pool(paths: list[Path], population: int | None) -> dict:
    """``--pool``: the unit records in ``paths`` pooled (:func:`gamma_units.pool`)."""
    from ntq_jax.experiment import gamma_units

    units = []
    for path in paths:
        try:
            d = json.loads(path.read_text())
        except (OSError, ValueError) as e:
            raise ScriptError(f"--pool: cannot read {path}: {e}") from None
        keys = {"queries", "non_trivial", "seed", *gamma_units.POOL_KEYS}
        if not isinstance(d, dict) or not keys <= set(d):
            raise ScriptError(f"--pool: {path} is not a result of measure_gamma.py --json")
        units.append(d)
    try:
        return gamma_units.pool(units, population)
    except UsageError as e:
        raise ScriptError(f"--pool: {e}") from None


def _pool_only(args) -> int:
    """``--pool``: pool the unit records, print the estimate, write ``--json``."""
    if args.json is None:
        raise ScriptError("--pool needs --json (the file the pooled estimate is written to)")
    check_writable(args.json, "--json")
    from ntq_jax import artifacts

    pooled = _read_pool(args.pool, args.population)
    _report_pooled(pooled)
    artifacts.write_json(args.json, pooled)
    return 0


def _report_pooled(pooled: dict) -> None:
    _report_json(pooled)
    print(
        f"pooled from {pooled['units']} units (seeds {pooled['seeds'][0]}..{pooled['seeds'][-1]})"
    )
    if "worlds" in pooled:
        _report_worlds(pooled["worlds"])
        if pooled["worlds"]["shared_queries"]:
            print(
                "warning: some envs were measured with the same seed (one query stream in "
                "several worlds): the 95% CI above is too narrow; the mean's interval "
                "allows for it"
            )


def _setup(args, name: str):
    """The environment ``name`` and the chunk of ``args`` (default: by robot), with JAX's
    persistent compilation cache on unless ``--no-compile-cache``."""
    import ntq_jax as nj
    from ntq_jax import artifacts
    from ntq_jax.gamma import default_chunk
    from ntq_jax.geometry import World3D

    if not args.no_compile_cache:
        artifacts.enable_compile_cache()
    env = nj.make_env(name)
    if args.chunk is not None:
        return env, args.chunk
    return env, ARM3D_CHUNK if isinstance(env.world, World3D) else default_chunk(
        env.robot, env.world
    )


def _bar(args, total: int, desc: str):
    from tqdm import tqdm

    return tqdm(
        total=total,
        unit="q",
        unit_scale=True,
        disable=args.no_progress,
        desc=f"gamma_nt {desc}",
        file=sys.stderr,
    )


def _measure(
    env, args, queries: int, chunk: int, eta, seed: int, quiet: bool = False
) -> dict | None:
    """gamma_nt of ``env`` over ``queries`` of ``seed``: its unit record, or None when
    interrupted (the estimate so far printed). ``quiet``: one line, not the full report."""
    import jax

    import ntq_jax as nj
    from ntq_jax.experiment import gamma_units

    cpu0 = _cpu_seconds()
    try:
        est = env.gamma_nt(
            jax.random.key(seed), queries, padding=args.padding, chunk=chunk, progress=eta
        )
    except KeyboardInterrupt as e:
        eta.bar.close()
        partial = getattr(e, "estimate", None)
        if partial is None:
            print("interrupted before the first chunk was counted: no estimate", file=sys.stderr)
        else:
            print(
                f"interrupted after {partial.queries:,} of {queries:,} queries; the estimate so far:"
            )
            _report(env, args.padding, partial)
        return None
    cpu = _cpu_seconds() - cpu0
    ahead, rate = eta.streaming()
    if quiet:
        lo, hi = est.ci95
        eta.bar.write(
            f"{env.name}: gamma_nt = {est.gamma:.6f}  95% CI [{lo:.6f}, {hi:.6f}]  "
            f"{est.seconds:.0f} s, {cpu:.0f} cpu-s",
            file=sys.stdout,
        )
    else:
        eta.bar.close()
        _report(env, args.padding, est)
        if rate is not None:
            print(
                f"streaming: {rate:,.0f} queries/s after the first chunk ({ahead:.1f} s to it, "
                "compilation included)"
            )
        print(
            f"cpu time {cpu:.1f} s, {est.queries / max(cpu, 1e-9):,.0f} queries per cpu-second "
            "(compilation included; on a shared core the wall-clock rate is lower)"
        )
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
    return gamma_units.unit_record(
        env,
        est,
        padding=args.padding,
        seed=seed,
        chunk=chunk,
        cpu=cpu,
        ahead=ahead,
        rate=rate,
        version=nj.__version__,
        cpus=cpus,
    )


def _measure_family(args, members: list[str]) -> int:
    """``--env panda/<scene>``: one unit of ``--queries / len(members)`` per member (the
    ones of ``--problems``), each written beside ``--json`` as it finishes and skipped
    when already there; ``--json`` pools the units present after each one."""
    from ntq_jax import artifacts
    from ntq_jax.experiment import gamma_units

    if args.json is None:
        raise ScriptError(
            f"--env {args.env} needs --json (the scene's pooled estimate; its units, one per "
            "problem, are written in the folder of the same name beside it)"
        )
    check_writable(args.json, "--json")
    n = len(members)
    if args.queries % n:
        raise ScriptError(
            f"--queries of {args.env} must be a multiple of its {n} problems (each problem "
            f"gets --queries / {n}; e.g. 1e8 is 1e6 on each)"
        )
    per = args.queries // n
    bad = [k for k in args.problems or () if not 1 <= k <= n]
    if bad:
        raise ScriptError(f"--problems {bad[0]} is not a problem of {args.env} (1 to {n})")
    picked = members if args.problems is None else [members[k - 1] for k in args.problems]
    seeds = {name: gamma_units.member_seed(args.seed, i, n) for i, name in enumerate(members)}
    env, chunk = _setup(args, picked[0])
    settings = dict(queries=per, padding=args.padding, chunk=chunk)

    def unit(name):
        record = gamma_units.read_unit(gamma_units.unit_path(args.json, name))
        same = gamma_units.same_measurement(record, env=name, seed=seeds[name], **settings)
        return record if same else None

    def pool_present() -> dict | None:
        units = [u for u in map(unit, members) if u is not None]
        if not units:
            return None
        pooled = gamma_units.pool(units, population=n)
        artifacts.write_json(args.json, pooled)
        return pooled

    todo = [name for name in picked if unit(name) is None]
    for name in todo:
        path = gamma_units.unit_path(args.json, name)
        if path.exists():
            raise ScriptError(
                f"{path} holds another measurement (other queries, seed, padding or chunk, "
                f"or not a unit): give this series its own --json, or remove {path}"
            )
    folder = gamma_units.unit_path(args.json, members[0]).parent
    print(
        f"{args.env}: {n} problems, {per:,} queries on each (problem k seeded "
        f"{n} x {args.seed} + k - 1: independent queries); of the {len(picked)} asked, "
        f"{len(picked) - len(todo)} already in {folder}/, {len(todo)} to measure"
    )
    bar = _bar(args, per * len(todo), args.env)
    try:
        for i, name in enumerate(todo):
            env = env if env.name == name else _setup(args, name)[0]
            eta = _Eta(bar, per, args.max_hours, offset=i * per, after=(len(todo) - i - 1) * per)
            record = _measure(env, args, per, chunk, eta, seeds[name], quiet=True)
            if record is None:
                print(f"{name}'s unit not written (interrupted); the units written are kept")
                pool_present()
                return INTERRUPTED
            artifacts.write_json(gamma_units.unit_path(args.json, name), record)
            pool_present()
    finally:
        bar.close()
    pooled = pool_present()
    if pooled is None:
        raise ScriptError(f"no unit of {args.env} with these settings in {folder}/")
    _report_pooled(pooled)
    return 0


def _run(argv) -> int:
    args = _parser().parse_args(argv)
    if args.pool is not None:
        return _pool_only(args)
    if args.population is not None:
        raise ScriptError("--population needs --pool (it describes the pooled envs' family)")
    from ntq_jax.experiment import gamma_units

    members = gamma_units.family(args.env)
    if members is not None:
        return _measure_family(args, members)
    if args.problems is not None:
        raise ScriptError("--problems needs a scene (--env panda/<scene>), not one environment")
    if args.skip_existing and args.json is None:
        raise ScriptError("--skip-existing needs --json (the file a finished run wrote)")
    if args.json is not None:
        check_writable(args.json, "--json")
    from ntq_jax import artifacts

    env, chunk = _setup(args, args.env)
    if args.skip_existing:
        done = gamma_units.read_unit(args.json)
        settings = dict(queries=args.queries, padding=args.padding, seed=args.seed, chunk=chunk)
        if gamma_units.same_measurement(done, env=env.name, **settings):
            print(f"{args.json} already holds this measurement; not measured again")
            _report_json(done)
            return 0
    bar = _bar(args, args.queries, env.name)
    try:
        eta = _Eta(bar, args.queries, args.max_hours)
        record = _measure(env, args, args.queries, chunk, eta, args.seed)
    finally:
        bar.close()
    if record is None:
        if args.json is not None:
            print(f"{args.json} not written (interrupted)", file=sys.stderr)
        return INTERRUPTED
    if args.json:
        artifacts.write_json(args.json, record)
    return 0


def main(argv=None) -> int:
    """Runs the script through :func:`ntq_jax.experiment.cli.run_cli`: an expected error (a bad option, an
    unknown environment or bad map, too little free space, a path that cannot be written) is
    one ``error:`` line on stderr and exit code 2; Ctrl-C exits with code 130 without a
    traceback (during the estimate, after printing the estimate so far)."""
    from ntq_jax.queries import FreeSpaceTooSmall

    return run_cli(lambda: _run(argv), extra=(FreeSpaceTooSmall,))


if __name__ == "__main__":
    sys.exit(main())
