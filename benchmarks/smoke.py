#!/usr/bin/env python
"""Smoke speed check: the headline ratios of BENCHMARKS.md's summary table in a few seconds each.

    python benchmarks/smoke.py          # exit status 1 when a ratio misses its goal by > 20 %
    python benchmarks/smoke.py --json smoke.json

Started by a Python without the package (no ``jax`` or ``ntq_jax``), it runs itself again
under the repository's ``.venv`` (the environment ``.ci/run`` makes) when there is one,
else it ends with one ``error:`` line.

Runs when a development session stops, beside the other checks, so it must stay
well under 40 s of wall time on a 2-core machine, imports, tracing and
compilation included. On a 2.0 GHz AMD EPYC (AVX2) it takes 49-51 s the first
time (74 CPU seconds) and 33-35 s once the persistent compilation cache holds
its programs (44 CPU seconds, most of the rest being JAX's tracing, which no
cache keeps). Every figure is measured
side by side in this one process (baseline and ours interleaved, medians), at
small sizes, with the benchmark scripts' own functions (``bench_steer``,
``bench_gamma``, ``bench_graph_search``, ``bench_plan``, ``bench_data``). A ratio
fails when it is more than 20 % short of its goal: ``measured < 0.8 x goal`` for
a ">= goal" ratio, ``measured > goal / 0.8`` for a "<= goal" one; a row that
raises fails too. Rates (per second) and seconds are printed for information
only: machines differ 2-5x. Rows:

1. ``Env.steer_to`` (point robot, ``bench_steer.MAP``, padding 0, 2^23 device
   pairs) against ``bench_steer.numpy_steer`` (2^20 of the pairs), per-query
   rates; goal >= 30x (issue 47; the summary table's 100x is printed beside it).
2. gamma_nt's stream (valid queries/s) against the bare motion check (pairs/s) on
   point/3, padding 0: ``bench_gamma.bench_env`` with 2^20 pairs (cache-resident,
   see ``GAMMA_PAIRS``) and 2^24 queries; goal <= 1.0 (the former goal >= 0.5
   printed beside it, not judged).
3. certified against discretised ``Env.steer_to`` on the same 8,192 uniform valid
   pairs of rigid/3 at padding 0.4 (``bench_steer.bench_certified``); BENCHMARKS.md
   states no ratio goal: printed only.
4. A* per query against scipy's single-source Dijkstra on one roadmap of rigid/3
   (``bench_graph_search.bench_map``, 10,000 milestones, 100 queries); the floor
   is ``ROADMAP_FLOOR`` (why: see there); A*'s ms per query printed only.
5. the batched neural planner against a per-query loop of it (``bench_plan.bench``,
   point/0, 500 queries batched, 32 in the loop, an untrained PNet); goal >= 10x.
6. D0..D3 of point/0 with 100 queries per dataset (``ntq_jax.data``): seconds,
   information only.

Compilation: row 3's checks (the largest program here) compile in a second
thread, then row 6 runs there, beside row 5's first planner call in the main
thread (a warm-up whose figures are dropped; row 6's seconds are taken beside it,
information only in any case). Then rows 1-5 are measured one at a time with
nothing beside them. Compiled programs are kept in JAX's persistent compilation
cache (``~/.cache/ntq_jax/jax`` or ``$JAX_COMPILATION_CACHE_DIR``, as the
experiment scripts use; ``--no-compile-cache`` compiles everything afresh), so a
check run a second time on a machine skips most of its compilation. Writes
nothing but the optional ``--json`` file and the cache (row 6 generates into a
temporary folder, removed).
"""

from __future__ import annotations

import time

T_START = time.perf_counter()

import argparse  # noqa: E402  (the imports are part of the wall time this check reports)
import contextlib
import io
import os
import sys
import tempfile
import threading
import traceback
from importlib.util import find_spec

#: The virtual environment ``.ci/run`` makes in the repository (``python -m venv .venv``).
REPO_VENV = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), ".venv")


def _venv_python() -> str | None:
    """The repository's ``.venv`` Python when this interpreter is not it (else None)."""
    for rel in ("bin/python", "Scripts/python.exe"):
        path = os.path.join(REPO_VENV, rel)
        if os.path.isfile(path) and os.path.abspath(sys.prefix) != os.path.abspath(REPO_VENV):
            return path
    return None


if find_spec("jax") is None or find_spec("ntq_jax") is None:
    # run under the repository's virtual environment when there is one (once: the variable
    # stops a loop); otherwise an expected error, one line
    venv_python = None if os.environ.get("NTQ_SMOKE_REEXEC") else _venv_python()
    if venv_python is not None:
        os.environ["NTQ_SMOKE_REEXEC"] = "1"
        os.execv(venv_python, [venv_python, os.path.abspath(__file__), *sys.argv[1:]])
    sys.exit(
        f"error: {sys.executable} has no {'jax' if find_spec('jax') is None else 'ntq_jax'} "
        f"and {REPO_VENV} holds no environment to run in: run the check with the package's "
        "Python (pip install -e . first, or activate its virtual environment; bash .ci/run "
        "makes .venv)"
    )

import bench_data
import bench_gamma
import bench_graph_search
import bench_plan
import jax
import numpy as np
from bench_steer import MAP, bench_certified, numpy_steer
from common import interleaved, loadavg, machine

import ntq_jax as nj
from ntq_jax import artifacts, data

TOLERANCE = 0.8  # a ratio fails when it is more than 20 % short of its goal
# interleaved repeats (medians) per row; --reps N sets them all
# Rows 2 and 5 measured far from their goals (0.3x against <= 1x, 30-33x against >= 10x),
# so three repeats do; row 1 measured 26-44x against >= 30x and keeps five.
REPS = {"steer": 5, "gamma": 3, "certified": 5, "roadmap": 2, "plan": 3}

STEER_PAIRS = 1 << 23  # ~10^7 pairs for Env.steer_to: one compiled piece size (2^20 rows)
NUMPY_PAIRS = 1 << 20  # ~10^6 of them for NumPy, so that it stays quick
# gamma_nt: 2^24 queries per repeat (bench_gamma: 2^25). The bare check on 2^20 pairs (16 MB)
# rather than bench_gamma's 2^23 (128 MB): the stream makes its pairs in registers, so the
# check it runs is the cache-resident one. On this machine (AMD EPYC, AVX-512) the check
# ran 3-13x slower per pair on 2^23 pairs than on 2^20 (memory-bound, and more so the more
# the other processes use memory): the ratio then moved between 0.85 and 1.75 with the
# load, while the stream's own rate stayed put.
GAMMA_PAIRS, GAMMA_QUERIES = 1 << 20, 1 << 24
CERT_ENV, CERT_PADDING = "rigid/3", 0.4
CERT_MOTIONS = 8192  # one piece of the discretised check, 8 chunks of the certified one
ROADMAP_MILESTONES = 10_000  # BENCHMARKS.md measures 20,000 (see ROADMAP_FLOOR)
ROADMAP_QUERIES = 100  # Dijkstra's ~5 ms each (on a 2.0 GHz AMD EPYC) is most of the row
# The A* / Dijkstra goal. BENCHMARKS.md's summary table states the search's goal as an
# absolute (<= 0.5 ms per query amortised, printed here for information); its side-by-side
# ratio to scipy's Dijkstra on a 20,000-milestone roadmap was 22-27x on one thread and
# 33-42x on two. Dijkstra grows its complete tree over every milestone while A* stops at
# the goal, so the ratio grows with the roadmap: on this check's 10,000 milestones it
# measured 11-17x in nine runs on this machine under load (2 threads; 6-7x at 2,000
# milestones). A floor of 10x (failing below 8x) leaves room for machine and load and
# still catches a search that settles most of the roadmap per query, as Dijkstra does.
ROADMAP_FLOOR = 10.0
# The batched planner amortises over its batch: on 64 queries it measured 5x the loop, on
# 256 11x, on 500 (BENCHMARKS.md's size) 9-28x under load. So the batch is BENCHMARKS.md's
# 500 queries (0.1-0.3 s to plan, compiled once either way) and the loop runs 32 of them,
# scaled, as bench_plan.py does with --loop-queries.
PLAN_ENV, PLAN_QUERIES, PLAN_LOOP_QUERIES = "point/0", 500, 32
DATA_ENV, DATA_K = "point/0", 100
# Programs that took longer than this to compile are kept in the persistent compilation
# cache (the library's default is 2 s, for the experiment scripts).
CACHE_MIN_COMPILE_SECONDS = 0.5


def _verdict(value: float, goal: float | None, kind: str) -> str:
    """ "met", "short (within 20 %)", "FAIL" for a judged ratio; "info" otherwise."""
    if goal is None or kind == "info":
        return "info"
    met = value >= goal if kind == ">=" else value <= goal
    tolerated = value >= TOLERANCE * goal if kind == ">=" else value <= goal / TOLERANCE
    return "met" if met else ("short (within 20 %)" if tolerated else "FAIL")


def _row(
    name: str,
    value: float,
    unit: str,
    goal: float | None = None,
    kind: str = "info",
    note: str = "",
) -> dict:
    return {
        "name": name,
        "value": float(value),
        "unit": unit,
        "goal": goal,
        "kind": kind,
        "verdict": _verdict(value, goal, kind),
        "note": note,
    }


def _fmt(v: float, unit: str) -> str:
    if v != v:  # NaN: the row raised
        return "ERROR"
    if unit == "x":
        return f"{v:.3g}x" if v < 100 else f"{v:,.0f}x"
    if unit == "s":
        return f"{v:.2f} s"
    if unit == "ms":
        return f"{v:.3f} ms"
    return f"{v:.3g} {unit}"


def print_row(r: dict) -> None:
    goal = "" if r["goal"] is None else f"{r['kind']} {_fmt(r['goal'], r['unit'])}"
    note = f"  ({r['note']})" if r["note"] else ""
    print(
        f"{r['name']:<52} {_fmt(r['value'], r['unit']):>12}  {goal:<11} {r['verdict']}{note}",
        flush=True,
    )


@contextlib.contextmanager
def recorded_medians(module):
    """``module.interleaved`` replaced, for the block, by one that also keeps its medians
    (for a benchmark function that prints its figures instead of returning them)."""
    got: dict = {}

    def recording(cases, reps):
        got.update(interleaved(cases, reps))
        recording.cores = interleaved.cores
        return dict(got)

    module.interleaved = recording
    try:
        yield got
    finally:
        module.interleaved = interleaved


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            info = dict(
                (k.strip(), v.strip()) for k, v in (line.split(":", 1) for line in f if ":" in line)
            )
    except OSError:
        return "unknown CPU"
    flags = info.get("flags", "").split()
    simd = "AVX-512" if "avx512f" in flags else ("AVX2" if "avx2" in flags else "no AVX2")
    return f"{info.get('model name', '?')}, {simd}"


# ---------------------------------------------------------------------------
# The rows
# ---------------------------------------------------------------------------


def steer_vs_numpy(reps: int) -> tuple[list[dict], dict]:
    """Row 1: the public point-robot steer_to against the vectorised NumPy slab test."""
    env = nj.Env.from_json(MAP)
    lo, hi = env.world.bounds[:, 0], env.world.bounds[:, 1]
    a, b = (
        lo + jax.random.uniform(k, (STEER_PAIRS, 2)) * (hi - lo)
        for k in jax.random.split(jax.random.key(0))
    )
    a_np, b_np = np.asarray(a[:NUMPY_PAIRS]), np.asarray(b[:NUMPY_PAIRS])
    boxes, bounds = np.asarray(env.world.boxes).tolist(), np.asarray(env.world.bounds).tolist()
    t = interleaved(
        {
            "api": lambda: env.steer_to(a, b, padding=0.0),
            "numpy": lambda: numpy_steer(a_np, b_np, boxes, bounds, 0.0),
        },
        reps,
    )
    ours, base = STEER_PAIRS / t["api"], NUMPY_PAIRS / t["numpy"]
    detail = {
        "seconds": t,
        "cores": dict(interleaved.cores),
        "pairs": STEER_PAIRS,
        "numpy_pairs": NUMPY_PAIRS,
    }
    return [
        _row(
            "1. steer_to (point, padding 0) / NumPy",
            ours / base,
            "x",
            30.0,
            ">=",
            f"{ours:.3g} vs {base:.3g} queries/s; cores {interleaved.cores['api']:.2f} / "
            f"{interleaved.cores['numpy']:.2f}; table: 100x, issue 47: 30x",
        )
    ], detail


def gamma_vs_check(reps: int) -> tuple[list[dict], dict]:
    """Row 2: gamma_nt's stream against the bare check it runs (bench_gamma's ratio)."""
    r = bench_gamma.bench_env("point/3", 0.0, reps, GAMMA_PAIRS, GAMMA_QUERIES)
    ratio = r["ratio"]
    note = (
        f"{r['gamma_queries_per_second']:.3g} valid queries/s vs {r['check_per_second']:.3g} "
        f"pairs/s ({r['queries']:,} queries, {r['pairs']:,} pairs); former goal >= 0.5: "
        f"{'met' if ratio >= 0.5 else 'not met'}"
    )
    row = _row("2. gamma_nt stream / bare check (point/3, pad 0)", ratio, "x", 1.0, "<=", note)
    return [row], r


def certified_vs_discretised(reps: int) -> tuple[list[dict], list]:
    """Row 3: certified against discretised checks, same motions (no ratio goal: printed)."""
    rows = bench_certified(CERT_ENV, CERT_MOTIONS, reps, None, pad=CERT_PADDING)
    cert, disc, ratio = rows[0], rows[1], rows[2]["ratio"]
    return [
        _row(
            f"3. certified / discretised check ({CERT_ENV}, pad {CERT_PADDING:g})",
            ratio,
            "x",
            note=f"{cert['per_second']:,.0f} vs {disc['per_second']:,.0f} motions/s on "
            f"{CERT_MOTIONS:,}; no ratio goal (BENCHMARKS.md: 0.61x at 10^5 uniform valid pairs)",
        )
    ], rows


def astar_vs_dijkstra(reps: int) -> tuple[list[dict], dict]:
    """Row 4: the roadmap's A* against scipy's Dijkstra, same roadmap and queries."""
    args = argparse.Namespace(
        milestones=ROADMAP_MILESTONES,
        queries=ROADMAP_QUERIES,
        reps=reps,
        threads=os.cpu_count(),
        cache_dir=None,
    )
    out = io.StringIO()
    with recorded_medians(bench_graph_search) as med, contextlib.redirect_stdout(out):
        bench_graph_search.bench_map(CERT_ENV, args)
    ms = 1e3 * med["astar"] / ROADMAP_QUERIES
    ratio = med["dijkstra"] / med["astar"]
    return [
        _row(
            f"4. A* / scipy Dijkstra ({CERT_ENV}, {ROADMAP_MILESTONES:,} milestones)",
            ratio,
            "x",
            ROADMAP_FLOOR,
            ">=",
            f"{ROADMAP_QUERIES} queries, {os.cpu_count()} threads; floor, see ROADMAP_FLOOR",
        ),
        _row(
            "4. roadmap search, A* ms per query (amortised)",
            ms,
            "ms",
            note="goal <= 0.5 ms at 20,000 milestones, information only",
        ),
    ], {"medians": dict(med), "printed": out.getvalue()}


def batched_vs_loop(reps: int) -> tuple[list[dict], list]:
    """Row 5: the batched neural planner against a per-query loop of the same planner."""
    runs = [_plan_once() for _ in range(reps)]
    med = {
        k: float(np.median([r[k] for r in runs]))
        for k in ("speedup", "batched_seconds_per_query", "loop_seconds_per_query")
    }
    return [
        _row(
            f"5. batched planner / per-query loop ({PLAN_ENV})",
            med["speedup"],
            "x",
            10.0,
            ">=",
            f"medians of {reps}: {med['batched_seconds_per_query'] * 1e3:.2f} vs "
            f"{med['loop_seconds_per_query'] * 1e3:.2f} ms/query; {PLAN_QUERIES} queries, "
            f"the loop on {PLAN_LOOP_QUERIES}; untrained PNet",
        )
    ], runs


def data_generation() -> tuple[list[dict], dict]:
    """Row 6: D0..D3 of a tiny point/0 run, seconds (information only)."""
    cfg = bench_data.load_config(
        bench_data.parse_args(["--env", DATA_ENV, "--k", str(DATA_K), "--gamma-queries", "100000"])
    )
    with tempfile.TemporaryDirectory(prefix="ntq_smoke_") as out:
        t0 = time.perf_counter()
        from ntq_jax.experiment import config as C

        s = data.generate_datasets(
            nj.make_env(DATA_ENV),
            C.data_options(cfg, DATA_ENV),
            out,
            env_name=DATA_ENV,
            progress=False,
            figure=False,
        )
        secs = time.perf_counter() - t0
    stages = ", ".join(f"{k} {s['timings'][k]:.1f}" for k in ("sample", "plan", "gamma"))
    return [
        _row(
            f"6. data generation D0..D3 ({DATA_ENV}, K = {DATA_K})",
            secs,
            "s",
            note=f"{s['planned_queries']} planned queries; {stages} s; compilation "
            "included; beside row 5's warm-up",
        )
    ], {"timings": s["timings"]}


def warm_certified(seconds: dict) -> None:
    """Compiles row 3's programs: the measurement's own call, once (an error shows in row 3)."""
    t0 = time.perf_counter()
    with contextlib.suppress(Exception):
        bench_certified(CERT_ENV, CERT_MOTIONS, 1, None, pad=CERT_PADDING)
    seconds["warm-up: certified (thread)"] = time.perf_counter() - t0


def warm_planner() -> tuple[list[dict], dict]:
    """Compiles row 5's programs: the measurement's own call with a loop of one query
    (the loop's single-query shapes compile all the same), its figures discarded."""
    return [], bench_plan.bench(PLAN_ENV, queries=PLAN_QUERIES, loop_queries=1)


def _plan_once() -> dict:
    return bench_plan.bench(PLAN_ENV, queries=PLAN_QUERIES, loop_queries=PLAN_LOOP_QUERIES)


# ---------------------------------------------------------------------------


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--json", default=None, help="also write the rows and details to this file")
    ap.add_argument(
        "--reps",
        type=int,
        default=None,
        help=f"interleaved repeats of every row (default per row: {REPS})",
    )
    ap.add_argument(
        "--no-compile-cache",
        action="store_true",
        help="compile every program afresh instead of using JAX's persistent compilation "
        "cache (~/.cache/ntq_jax/jax, or $JAX_COMPILATION_CACHE_DIR)",
    )
    args = ap.parse_args(argv)
    reps = {k: args.reps or v for k, v in REPS.items()}
    if not args.no_compile_cache:
        artifacts.enable_compile_cache(min_compile_seconds=CACHE_MIN_COMPILE_SECONDS)
    t_import = time.perf_counter() - T_START
    load0 = loadavg()
    info = machine()
    print(
        f"smoke speed check, {info['date']}: {cpu_model()}, {info['cpu_count']} CPUs, load "
        f"{load0}; ntq_jax {info['git_revision']}{' (dirty tree)' if info['git_dirty'] else ''}, "
        f"jax {info['jax']}, numpy {info['numpy']}",
        flush=True,
    )
    print(f"{'ratio':<52} {'measured':>12}  {'goal':<11} verdict", flush=True)

    rows, details, seconds, cpu = [], {}, {"imports": t_import}, {}

    def run(name, fn, *a):
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            got, details[name] = fn(*a)
        except Exception as e:  # noqa: BLE001 - a broken row fails the check, the others still run
            traceback.print_exc()
            got = [
                {
                    "name": name,
                    "value": float("nan"),
                    "unit": "",
                    "goal": None,
                    "kind": "error",
                    "verdict": "FAIL",
                    "note": f"{type(e).__name__}: {e}",
                }
            ]
        seconds[name], cpu[name] = time.perf_counter() - t0, time.process_time() - c0
        for r in got:
            print_row(r)
            rows.append(r)

    # Warm-up in two threads: row 3's certified and discretised checks (the largest
    # compilation here; row 4's roadmap shares its discretised check and state sampler),
    # then row 6 (its seconds are information only), beside row 5's first planner call (its
    # compilation; its figures are discarded).
    def beside():
        warm_certified(seconds)
        run("6. data generation", data_generation)

    warm = threading.Thread(target=beside, daemon=True)
    warm.start()
    run("warm-up: planner", warm_planner)
    warm.join()
    # The measurements, one at a time, nothing beside them.
    run("1. steer_to / NumPy", steer_vs_numpy, reps["steer"])
    run("2. gamma_nt / bare check", gamma_vs_check, reps["gamma"])
    run("3. certified / discretised", certified_vs_discretised, reps["certified"])
    run("4. A* / Dijkstra", astar_vs_dijkstra, reps["roadmap"])
    run("5. batched / loop", batched_vs_loop, reps["plan"])

    failed = [r["name"] for r in rows if r["verdict"] == "FAIL"]
    judged = sum(r["kind"] in (">=", "<=", "error") for r in rows)
    wall = time.perf_counter() - T_START
    load1 = loadavg()
    print(
        "seconds: "
        + ", ".join(f"{k} {v:.1f}" for k, v in seconds.items())
        + f"; CPU {time.process_time():.1f} s; load {load0} -> {load1}",
        flush=True,
    )
    print(
        f"{'FAIL' if failed else 'PASS'}: {len(failed)} of {judged} judged ratios more than 20 % "
        f"short of their goals{' (' + '; '.join(failed) + ')' if failed else ''}; "
        f"total wall time {wall:.1f} s",
        flush=True,
    )
    if args.json:
        artifacts.write_json(
            args.json,
            {
                "machine": {**info, "cpu": cpu_model()},
                "load": [load0, load1],
                "rows": rows,
                "seconds": seconds,
                "cpu_seconds": cpu,
                "wall_seconds": wall,
                "passed": not failed,
                "details": details,
            },
            default=str,
        )
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
