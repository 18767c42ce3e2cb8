"""The report stage of ``bench_roadmap.py``: ``summary.md`` from the saved BIT* and roadmap results."""

from __future__ import annotations

import math
from pathlib import Path

from common import load_json, percentile

WORKERS = 2  # BIT*'s worker processes
MEMORY_GOAL_BYTES = 2 * 1024**3  # peak RSS of the roadmap at 50,000 milestones
GOAL_MEDIAN, GOAL_P90 = 1.0, 1.05  # roadmap cost / BIT* cost: median and 90th percentile


def slug(name: str) -> str:
    from ntq_jax.envs import env_slug

    return env_slug(name)


def _yes(b) -> str:
    return "—" if b is None else ("yes" if b else "**no**")


def compare(b: dict | None, r: dict | None) -> dict:
    """The per-map figures of the summary (None where a side is missing)."""
    import numpy as np

    row = {"bitstar": b is not None, "roadmap": r is not None}
    if b is not None:
        sb = np.asarray(b["status"]) == 0
        row.update(
            succ_b=float(sb.mean()),
            wall_b=b["wall_per_query"],
            n=len(sb),
            load_b=(b["loadavg_before"], b["loadavg_after"]),
            fb=b.get("n_fallback", 0),
            cpu_b=b.get("workers_cpu_per_budget"),
        )
    if r is not None:
        sr = np.asarray(r["status"]) == 0
        build, query = r.get("build_time"), r.get("query_time")
        if query is None and build is not None:
            query = r["wall_time"] - build
        row.update(
            succ_r=float(sr.mean()), wall_r=r["wall_per_query"], build_r=build, query_r=query
        )
    if b is not None and r is not None:
        if b["query_sha256"] != r["query_sha256"]:
            row["mismatch"] = True
            return row
        cb = np.array([np.inf if c is None else c for c in b["cost"]])
        cr = np.array([np.inf if c is None else c for c in r["cost"]])
        both = sb & sr & np.isfinite(cb) & np.isfinite(cr) & (cb > 0)
        ratio = cr[both] / cb[both]
        row.update(
            n_both=int(both.sum()),
            med=percentile(ratio, 50),
            p90=percentile(ratio, 90),
            goal_succ=row["succ_r"] >= row["succ_b"],
            goal_med=bool(both.any()) and percentile(ratio, 50) <= GOAL_MEDIAN,
            goal_p90=bool(both.any()) and percentile(ratio, 90) <= GOAL_P90,
        )
    return row


def _fmt(x, fmt: str) -> str:
    return "—" if x is None or (isinstance(x, float) and math.isnan(x)) else fmt.format(x)


def _notes(name: str, b: dict | None, r: dict | None, row: dict) -> list[str]:
    """The summary's notes on one map: missing or mismatched results, fallbacks, timings."""
    f = _fmt
    notes = []
    if row.get("mismatch"):
        notes.append(
            f"* {name}: the roadmap and BIT* files hold different queries "
            "(query sha256 differs): not compared; rerun one of them."
        )
    if b is None:
        notes.append(f"* {name}: BIT* result missing (`--stage bitstar`).")
    if r is None:
        notes.append(f"* {name}: roadmap result missing (`--stage roadmap`).")
    if row.get("fb"):
        notes.append(f"* {name}: {row['fb']} queries are the sampler's trivial fallback (kind 2).")
    if r is not None and (row.get("build_r") is not None or row.get("query_r") is not None):
        notes.append(
            f"* {name}: roadmap build {f(row.get('build_r'), '{:.2f}')} s, "
            f"query {f(row.get('query_r'), '{:.2f}')} s; options {r.get('options')}."
        )
    return notes


def _comparison_row(name: str, b: dict | None, r: dict | None, row: dict) -> str:
    """One map's line of the roadmap vs BIT* table."""
    f = _fmt
    budget = b["time_budget"] if b else None
    load = f"{row['load_b'][0][0]:.1f} / {row['load_b'][1][0]:.1f}" if b else "—"
    if b and b.get("loadavg_during"):
        load += f" (mean {b['loadavg_during']['mean']:.1f})"
    return (
        f"| {name} | {row.get('n', r['n_queries'] if r else '—')} | {f(budget, '{:g}')} | "
        f"{f(row.get('succ_b'), '{:.3f}')} | {f(row.get('succ_r'), '{:.3f}')} | "
        f"{f(row.get('n_both'), '{}')} | {f(row.get('med'), '{:.4f}')} | "
        f"{f(row.get('p90'), '{:.4f}')} | {f(row.get('wall_b'), '{:.3f}')} | "
        f"{f(row.get('wall_r'), '{:.4f}')} | {load} | {f(row.get('cpu_b'), '{:.2f}')} | "
        f"{_yes(row.get('goal_succ'))} | "
        f"{_yes(row.get('goal_med'))} | {_yes(row.get('goal_p90'))} |"
    )


def _comparison_table(envs: list[str], out: Path) -> tuple[list[str], list[str]]:
    """The roadmap vs BIT* table (with its heading and legend) and the notes on the maps."""
    lines = [
        "# Roadmap vs BIT* (benchmarks/bench_roadmap.py)",
        "",
        "Same non-trivial queries per map (data padding); BIT* at the paper's data budget "
        f"with {WORKERS} workers. Cost ratio = roadmap / BIT* per query, on queries both "
        "solved. Goals: success >= BIT*'s; median ratio <= 1.0; p90 <= 1.05.",
        "",
        "| map | queries | BIT* budget s | BIT* success | roadmap success | both solved | "
        "ratio median | ratio p90 | BIT* s/query | roadmap s/query | BIT* load before/after | "
        "BIT* CPU/budget | "
        "success >= | median <= 1.0 | p90 <= 1.05 |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|---|---|---|",
    ]
    notes = []
    for name in envs:
        s = slug(name)
        b = load_json(out / f"{s}_bitstar.json")
        r = load_json(out / f"{s}_roadmap.json")
        row = compare(b, r)
        notes += _notes(name, b, r, row)
        lines.append(_comparison_row(name, b, r, row))
    lines += [
        "",
        "BIT* load average: the 1-minute figure of os.getloadavg() before and after "
        "the map's run (2 cores; mean: sampled every 15 s during it). BIT* CPU/budget: "
        "CPU seconds its worker processes used / (queries x budget); BIT* stops on wall-clock "
        "time, so below ~1 it had less "
        "than a core per worker (other load) and explored less than on an idle machine.",
    ]
    return lines, notes


def _pools_table(envs: list[str], out: Path) -> list[str]:
    """The "Pools and memory" section: the pool timings and the peak memory per map."""
    f = _fmt
    lines = [
        "",
        "## Pools and memory",
        "",
        "| map | measurement | queries | plan s | goal s | met | solved | peak RSS GiB |",
        "|---|---|---:|---:|---:|---|---:|---:|",
    ]
    for name in envs:
        for which in ("pool", "memory"):
            rec = load_json(out / f"{slug(name)}_{which}.json")
            if rec is None:
                continue
            goal = rec.get("goal_seconds") if which == "pool" else None
            met = (
                (rec["wall_time"] <= goal)
                if goal
                else (rec["peak_rss_bytes"] < MEMORY_GOAL_BYTES if which == "memory" else None)
            )
            lines.append(
                f"| {name} | {which}"
                f"{' (' + str(rec['options'].get('milestones')) + ' milestones)' if which == 'memory' else ''}"
                f" | {rec['n_queries']} | {rec['wall_time']:.1f} | {f(goal, '{:g}')} | "
                f"{_yes(met)}{' (< 2 GiB)' if which == 'memory' else ''} | {rec['solved']} | "
                f"{rec['peak_rss_bytes'] / 2**30:.2f} |"
            )
    return lines


def stage_report(envs: list[str], args, out: Path) -> str:
    from ntq_jax import artifacts

    lines, notes = _comparison_table(envs, out)
    lines += _pools_table(envs, out)
    if notes:
        lines += ["", "Notes:", ""] + notes
    text = "\n".join(lines) + "\n"
    print(text, flush=True)
    artifacts.write_text(out / "summary.md", text)
    print(f"-> {out / 'summary.md'}", flush=True)
    return text
