#!/usr/bin/env python
"""Planning for the Panda: a query pool on one scene, MotionBenchMaker's problems, the peers.

    taskset -c 0 python benchmarks/bench_panda_plan.py pool                # 10,000 queries, cage/1
    taskset -c 0 python benchmarks/bench_panda_plan.py pool --env panda/table_pick/1
    taskset -c 0 python benchmarks/bench_panda_plan.py mbm                 # bitree, all 700 problems
    taskset -c 0 python benchmarks/bench_panda_plan.py compare --every 20  # bitree / roadmap / OMPL
    taskset -c 0 python benchmarks/bench_panda_plan.py vamp                # VAMP, when importable
    python benchmarks/bench_panda_plan.py report                           # summary.md

Every stage writes a JSON file to ``--out`` (default ``results/panda_plan/``) with the
machine, the git revision, the load average and every figure twice, wall-clock and
process CPU seconds (the machine is shared: pin to one core and compare CPU time).

``pool``
    ``env.sample_queries(key(0), --queries, p_nt=0.5)`` on ``--env`` (what data
    generation plans), then ``ntq_jax.plan(env, q, "roadmap", check="certified")``
    with the serial arm's defaults, twice in one process, each on a fresh ``Env``
    (so the roadmap is rebuilt): the first run compiles, the second is the figure
    (goal: <= 60 s). -> ``pool_<env>.json``: sampling time, both runs' wall/CPU, the
    stage times of ``info``, success (all, non-trivial), statuses, costs.
``mbm``
    MotionBenchMaker's 7 scenes x 100 problems (``--scenes``, ``--numbers``), one
    ``Env`` per problem, planned by ``--planner`` (``bitree``) with ``check``
    (certified): per problem status, cost, waypoints, wall/CPU, attempts. The first
    problem of each scene compiles (its scene's obstacle counts); medians exclude it
    (goal: >= 99 % solved with every segment certified, median <= 20 ms).
    -> ``mbm_<planner>.json``.
``compare``
    Every ``--every``-th problem of each scene, planned by ``bitree`` (certified), by a
    roadmap of its own (``--roadmap-milestones``, certified) and by OMPL's RRT-Connect +
    simplification on the package's checks (``rrtconnect``, discretised, then its paths
    certified separately): success and the per-problem cost ratio to OMPL
    (goal: ours within 10 %). -> ``compare.json``.
``vamp``
    VAMP's RRT-Connect + simplification (:mod:`ntq_jax.planners.vamp_bridge`) on the same
    problems as ``mbm``, its paths checked by the package (discretised and certified);
    a one-line note when ``import vamp`` fails. -> ``mbm_vamp.json``.
``report``
    ``summary.md`` from the JSON files.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from common import finite_or_none, loadavg, machine, percentile

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "results" / "panda_plan"


class Clock:
    """Wall and process-CPU seconds of a ``with`` block."""

    def __enter__(self):
        self.w0, self.c0 = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *exc):
        self.wall = time.perf_counter() - self.w0
        self.cpu = time.process_time() - self.c0


def _round(x, nd=4):
    return None if x is None else round(float(x), nd)


def _stats(xs) -> dict:
    xs = [x for x in xs if x is not None]
    if not xs:
        return {"n": 0}
    return {
        "n": len(xs),
        "median": _round(np.median(xs)),
        "p90": _round(percentile(xs, 90)),
        "mean": _round(np.mean(xs)),
        "max": _round(max(xs)),
    }


def _write(path: Path, data: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(data, indent=1, default=_plain))
    tmp.replace(path)
    print(f"wrote {path}", flush=True)


def _plain(x):
    if isinstance(x, np.ndarray):
        return x.tolist() if x.size <= 64 else f"<array {x.shape}>"
    if isinstance(x, (np.integer, np.floating, np.bool_)):
        return x.item()
    return str(x)


def _info(info: dict) -> dict:
    return {
        k: (_round(v) if isinstance(v, float) else v)
        for k, v in info.items()
        if not isinstance(v, np.ndarray) or v.size <= 64
    }


# ---------------------------------------------------------------------------
# pool
# ---------------------------------------------------------------------------


def stage_pool(args) -> None:
    import jax

    import ntq_jax as nj
    from ntq_jax.types import STATUS_NAMES

    env = nj.make_env(args.env)
    with Clock() as c:
        q, kind = env.sample_queries(jax.random.key(0), args.queries, p_nt=0.5)
    sampling = {"wall": _round(c.wall, 2), "cpu": _round(c.cpu, 2)}
    print(
        f"{args.env}: {args.queries} queries sampled in {c.wall:.1f} s ({c.cpu:.1f} cpu-s)",
        flush=True,
    )
    runs = []
    for r in range(args.runs):
        fresh = nj.make_env(args.env)  # a new Env: its roadmap is built again
        load0 = loadavg()
        with Clock() as c:
            res = nj.plan(fresh, q, "roadmap", check=args.check)
        nt = kind == 1
        run = {
            "run": r,
            "wall": _round(c.wall, 2),
            "cpu": _round(c.cpu, 2),
            "load_before": load0,
            "load_after": loadavg(),
            "solved": _round(res.solved.mean()),
            "solved_nt": _round(res.solved[nt].mean()),
            "solved_uniform": _round(res.solved[~nt].mean()),
            "status": {
                STATUS_NAMES[s]: int((res.status == s).sum()) for s in np.unique(res.status)
            },
            "cost_median": _round(np.median(res.costs[res.solved])),
            "waypoints_median": _round(np.median(res.lengths[res.solved])),
            "info": _info(res.info),
        }
        runs.append(run)
        print(
            f"  run {r}: {c.wall:.1f} s wall, {c.cpu:.1f} cpu-s; solved {run['solved']:.4f} "
            f"(non-trivial {run['solved_nt']:.4f}); {run['status']}",
            flush=True,
        )
    slug = args.env.replace("/", "_")
    _write(
        Path(args.out) / f"pool_{slug}.json",
        {
            "stage": "pool",
            "env": args.env,
            "queries": args.queries,
            "p_nt": 0.5,
            "check": args.check,
            "sampling": sampling,
            "runs": runs,
            "command": " ".join(sys.argv),
            "machine": machine(),
        },
    )


# ---------------------------------------------------------------------------
# mbm
# ---------------------------------------------------------------------------


def _problems(args):
    from ntq_jax.scenes import mbm

    scenes = args.scenes or list(mbm.SCENES)
    lo, hi = (int(x) for x in args.numbers.split("-"))
    return [(s, n) for s in scenes for n in range(lo, hi + 1) if (n - lo) % args.every == 0]


def _plan_problem(planner: str, name: str, check: str, options: dict):
    import ntq_jax as nj

    env = nj.make_env(name)
    with Clock() as c:
        res = nj.plan(env, env.query[None], planner, check=check, **options)
    return env, res, c


def stage_mbm(args) -> None:
    from ntq_jax.types import STATUS_NAMES

    rows, seen = [], set()
    options = json.loads(args.options) if args.options else {}
    for scene, number in _problems(args):
        name = f"panda/{scene}/{number}"
        env, res, c = _plan_problem(args.planner, name, args.check, options)
        first = scene not in seen  # the scene's first problem compiles its programs
        seen.add(scene)
        row = {
            "scene": scene,
            "number": number,
            "first": first,
            "status": STATUS_NAMES[int(res.status[0])],
            "cost": finite_or_none(res.costs[0]),
            "waypoints": int(res.lengths[0]),
            "wall": _round(c.wall),
            "cpu": _round(c.cpu),
        }
        for k in ("attempts", "iterations"):
            if k in res.info:
                row[k] = int(np.asarray(res.info[k])[0])
        if "vamp_times" in res.info:  # VAMP's own clock and path, before the package's check
            own = float(np.asarray(res.info["planner_costs"])[0])
            row["vamp_ms"] = _round(float(np.asarray(res.info["vamp_times"])[0]) * 1e3)
            row["vamp_found"] = bool(np.isfinite(own))
            row["vamp_cost"] = finite_or_none(own)
        rows.append(row)
        print(
            f"  {name}: {row['status']} cost {row['cost']} wall {c.wall * 1e3:.1f} ms "
            f"cpu {c.cpu * 1e3:.1f} ms{' (first: compiles)' if first else ''}",
            flush=True,
        )
    _write(
        Path(args.out) / f"mbm_{args.planner}.json",
        {
            "stage": "mbm",
            "planner": args.planner,
            "check": args.check,
            "options": options,
            "summary": _mbm_summary(rows),
            "problems": rows,
            "command": " ".join(sys.argv),
            "load_after": loadavg(),
            "machine": machine(),
        },
    )


def _vamp_summary(valid: list[dict]) -> dict:
    """VAMP's own account (``vamp`` rows): paths found, its planning + simplification time
    (its clock, every problem: VAMP compiles nothing at run time), and how many of its
    paths the package's check accepted; ``{}`` for the other planners."""
    rows = [r for r in valid if "vamp_ms" in r]
    if not rows:
        return {}
    found = [r for r in rows if r["vamp_found"]]
    return {
        "vamp_found": len(found),
        "vamp_own_ms": _stats([r["vamp_ms"] for r in rows]),
        "vamp_cost": _stats([r["vamp_cost"] for r in found]),
        "vamp_paths_accepted": sum(r["status"] == "solved" for r in found),
    }


def _mbm_summary(rows: list[dict]) -> dict:
    valid = [r for r in rows if r["status"] != "invalid"]
    warm = [r for r in valid if not r["first"]]
    by_scene = {}
    for s in dict.fromkeys(r["scene"] for r in rows):
        v = [r for r in valid if r["scene"] == s]
        by_scene[s] = {"problems": len(v), "solved": sum(r["status"] == "solved" for r in v)}
    solved = sum(r["status"] == "solved" for r in valid)
    return {
        "problems": len(rows),
        "invalid": len(rows) - len(valid),
        "valid": len(valid),
        "solved": solved,
        "success": _round(solved / max(1, len(valid))),
        "wall_s_excluding_first": _stats([r["wall"] for r in warm]),
        "cpu_s_excluding_first": _stats([r["cpu"] for r in warm]),
        "first_of_scene_wall_s": _stats([r["wall"] for r in valid if r["first"]]),
        "cost": _stats([r["cost"] for r in valid if r["status"] == "solved"]),
        **_vamp_summary(valid),
        "by_scene": by_scene,
    }


# ---------------------------------------------------------------------------
# compare
# ---------------------------------------------------------------------------


def stage_compare(args) -> None:
    from ntq_jax.planners.verify import check_paths
    from ntq_jax.types import STATUS_NAMES

    planners = {
        "bitree": ("bitree", "certified", {}),
        "roadmap": ("roadmap", "certified", {"milestones": args.roadmap_milestones}),
        "rrtconnect": ("rrtconnect", "discretized", {}),
    }
    if args.skip:
        for k in args.skip:
            planners.pop(k, None)
    rows, seen = [], set()
    for scene, number in _problems(args):
        name = f"panda/{scene}/{number}"
        row = {"scene": scene, "number": number, "first": scene not in seen}
        seen.add(scene)
        for label, (planner, check, opts) in planners.items():
            env, res, c = _plan_problem(planner, name, check, opts)
            r = {
                "status": STATUS_NAMES[int(res.status[0])],
                "cost": finite_or_none(res.costs[0]),
                "waypoints": int(res.lengths[0]),
                "wall": _round(c.wall),
                "cpu": _round(c.cpu),
            }
            if check != "certified" and res.solved[0]:  # does its path pass the certified check?
                ok, _ = check_paths(env, res.paths, res.lengths, env.padding, "certified")
                r["certified"] = bool(ok[0])
            row[label] = r
        rows.append(row)
        print(
            f"  {name}: "
            + "; ".join(
                f"{k} {v['status']} {v['cost']} {v['cpu'] * 1e3:.0f} ms"
                for k, v in row.items()
                if isinstance(v, dict)
            ),
            flush=True,
        )
    _write(
        Path(args.out) / "compare.json",
        {
            "stage": "compare",
            "planners": {k: [p, c, o] for k, (p, c, o) in planners.items()},
            "summary": _compare_summary(rows, list(planners)),
            "problems": rows,
            "command": " ".join(sys.argv),
            "load_after": loadavg(),
            "machine": machine(),
        },
    )


def _compare_summary(rows: list[dict], labels: list[str]) -> dict:
    out = {}
    warm = [r for r in rows if not r["first"]]
    for k in labels:
        valid = [r for r in rows if r[k]["status"] != "invalid"]
        s = {
            "problems": len(valid),
            "solved": sum(r[k]["status"] == "solved" for r in valid),
            "cpu_s_excluding_first": _stats([r[k]["cpu"] for r in warm]),
            "wall_s_excluding_first": _stats([r[k]["wall"] for r in warm]),
        }
        if any("certified" in r[k] for r in valid):
            s["solved_and_certified"] = sum(bool(r[k].get("certified")) for r in valid)
        if k != "rrtconnect" and "rrtconnect" in labels:
            both = [
                r[k]["cost"] / r["rrtconnect"]["cost"]
                for r in valid
                if r[k]["status"] == "solved" and r["rrtconnect"]["status"] == "solved"
            ]
            s["cost_ratio_to_ompl"] = _stats(both)
            s["cost_ratio_to_ompl"]["geomean"] = (
                _round(float(np.exp(np.mean(np.log(both))))) if both else None
            )
        out[k] = s
    return out


# ---------------------------------------------------------------------------
# vamp
# ---------------------------------------------------------------------------


def stage_vamp(args) -> None:
    try:
        from ntq_jax.planners import vamp_bridge

        vamp_bridge.require_vamp()
    except ImportError as e:
        print(
            f"vamp: not importable here ({e}); see ntq_jax/planners/vamp_bridge.py for the build",
            flush=True,
        )
        return
    args.planner = "vamp"
    stage_mbm(args)


# ---------------------------------------------------------------------------
# report
# ---------------------------------------------------------------------------


def stage_report(args) -> None:
    out = Path(args.out)
    lines = [
        "# Planning for the Panda (benchmarks/bench_panda_plan.py)",
        "",
        "Wall-clock and process CPU seconds on the shared 2-core machine, pinned to core 0 "
        "(`taskset -c 0`); CPU time is the comparable figure.",
        "",
    ]
    for f in sorted(out.glob("pool_*.json")):
        d = json.loads(f.read_text())
        lines += [
            f"## Query pool: {d['env']}, {d['queries']} queries (p_nt 0.5), check {d['check']}",
            "",
            f"Sampling: {d['sampling']['wall']} s wall, {d['sampling']['cpu']} cpu-s.",
            "",
            "| run | wall s | cpu s | solved | non-trivial | uniform | statuses | "
            "repaired | replanned | rejected | unreachable ends |",
            "|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for r in d["runs"]:
            i = r["info"]
            lines.append(
                f"| {r['run']}{' (compiles)' if r['run'] == 0 else ''} | {r['wall']} | "
                f"{r['cpu']} | {r['solved']} | {r['solved_nt']} | {r['solved_uniform']} | "
                f"{r['status']} | {i.get('repaired')} | {i.get('replanned')} | "
                f"{i.get('rejected')} | {i.get('unreachable_ends')} |"
            )
        last = d["runs"][-1]["info"]
        lines += [
            "",
            "Stage wall seconds of the last run: "
            + ", ".join(
                f"{k} {last[k]}"
                for k in ("build_time", "search_time", "smooth_time", "check_time")
                if k in last
            )
            + ".",
            "",
        ]
    for f in sorted(out.glob("mbm_*.json")):
        d = json.loads(f.read_text())
        s = _mbm_summary(d["problems"])
        lines += [
            f"## MotionBenchMaker: {d['planner']} (check {d['check']})",
            "",
            f"{s['solved']} / {s['valid']} valid problems solved ({s['success']}); "
            f"{s['invalid']} invalid.",
            "",
            "| per problem, first of each scene excluded | median | p90 | max |",
            "|---|---|---|---|",
            f"| wall ms | {_ms(s['wall_s_excluding_first'], 'median')} | "
            f"{_ms(s['wall_s_excluding_first'], 'p90')} | "
            f"{_ms(s['wall_s_excluding_first'], 'max')} |",
            f"| cpu ms | {_ms(s['cpu_s_excluding_first'], 'median')} | "
            f"{_ms(s['cpu_s_excluding_first'], 'p90')} | "
            f"{_ms(s['cpu_s_excluding_first'], 'max')} |",
            "",
            f"Path cost (joint-space length) median {s['cost'].get('median')}; first "
            f"problem of a scene (compiles) median "
            f"{s['first_of_scene_wall_s'].get('median')} s wall.",
            "",
            "| scene | solved |",
            "|---|---|",
        ]
        lines += [f"| {k} | {v['solved']} / {v['problems']} |" for k, v in s["by_scene"].items()]
        lines.append("")
        if "vamp_found" in s:  # VAMP's own account, before the package's check
            own = s["vamp_own_ms"]
            lines += [
                f"VAMP's own account: a path for {s['vamp_found']} / {s['valid']} valid "
                f"problems; planning + simplification by its clock median {own['median']} ms, "
                f"p90 {own['p90']} ms, max {own['max']} ms (every problem: VAMP compiles "
                f"nothing at run time); path cost median {s['vamp_cost'].get('median')}; "
                f"{s['vamp_paths_accepted']} of its paths pass the package's {d['check']} "
                "check (the solved count above). The per-problem times above add the "
                "package's environment and that check.",
                "",
            ]
    f = out / "compare.json"
    if f.exists():
        d = json.loads(f.read_text())
        d["summary"] = _compare_summary(d["problems"], list(d["planners"]))
        lines += [
            "## Same problems, three planners (every segment of ours certified; OMPL's "
            "discretised, then certified separately)",
            "",
            "| planner | solved | certified | cpu ms median | cost / OMPL median | geomean | p90 |",
            "|---|---|---|---|---|---|---|",
        ]
        for k, s in d["summary"].items():
            r = s.get("cost_ratio_to_ompl", {})
            lines.append(
                f"| {k} | {s['solved']} / {s['problems']} | "
                f"{s.get('solved_and_certified', s['solved'])} | "
                f"{_ms(s['cpu_s_excluding_first'], 'median')} | {r.get('median', '')} | "
                f"{r.get('geomean', '')} | {r.get('p90', '')} |"
            )
        lines.append("")
    (out / "summary.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def _ms(s: dict, key: str) -> str:
    v = s.get(key)
    return "" if v is None else f"{v * 1e3:.1f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("stage", choices=("pool", "mbm", "compare", "vamp", "report"))
    ap.add_argument("--out", default=str(OUT))
    ap.add_argument("--env", default="panda/cage/1")
    ap.add_argument("--queries", type=int, default=10_000)
    ap.add_argument("--runs", type=int, default=2)
    ap.add_argument("--check", default="certified")
    ap.add_argument("--planner", default="bitree")
    ap.add_argument("--options", default="", help="planner options as JSON")
    ap.add_argument("--scenes", nargs="*")
    ap.add_argument("--numbers", default="1-100")
    ap.add_argument("--every", type=int, default=1)
    ap.add_argument("--roadmap-milestones", type=int, default=1000)
    ap.add_argument("--skip", nargs="*", help="compare: planners left out")
    args = ap.parse_args()
    {
        "pool": stage_pool,
        "mbm": stage_mbm,
        "compare": stage_compare,
        "vamp": stage_vamp,
        "report": stage_report,
    }[args.stage](args)


if __name__ == "__main__":
    main()
