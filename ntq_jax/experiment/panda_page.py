"""Beyond the paper: a 7-DoF arm. ``results/panda/REPRODUCTION.md`` from committed summaries.

The paper tests non-trivial query sampling up to a planar 6-link arm. The same
experiment on the Franka Panda in MotionBenchMaker's scenes (``configs/panda.yaml``:
one problem's world per scene, K_train 5,000 per dataset, K_test 500 + 500, three
training seeds) is summarised here, in the layout of the paper's tables, from the
summaries ``scripts/reproduce.py --config configs/panda.yaml --results results/panda``
writes: ``<root>/panda/<map>/summary.json`` (main run, training seed 0),
``<root>/panda/<map>/seeds/train_seed_<k>/summary.json`` (the same data, another
training seed) and beside each ``problems.json`` (the scene's MotionBenchMaker
problems as a third query kind, :mod:`ntq_jax.experiment.problems`).

Sections, each from the summaries alone (no clock, fixed float formats):

1. **The verdict at 7 DoF**: PNet_3 - PNet_0 in success on non-trivial test queries
   (the paper's headline comparison) per scene and pooled over the scenes, with the
   training seed as a random effect (:class:`ntq_jax.experiment.quantities.Seeds`,
   :func:`ntq_jax.seed_effects.combine`), Holm-adjusted p over the rows of the table
   (:func:`ntq_jax.multiplicity.holm`), and the verdict by the rule of
   ``results/paper/REPRODUCTION.md`` (:func:`ntq_jax.experiment.verdicts.verdict`: holds
   / contradicted / unresolved at alpha 0.05 on the adjusted p; there is no paper value
   at 7 DoF, so no magnitude test). The same on uniform queries below it.
2. **Success and cost per PNet**: every model's success ratio and cost ratio per query
   kind, the mean over the seeds with their range, per scene.
3. **MotionBenchMaker's own problems**: each PNet's (and best-of-4's) solved fraction of
   the scene's valid problems, beside OMPL's RRT-Connect (and VAMP's, where built).
4. **Data and time**: gamma_nt, dataset sizes, time per stage and cell.
"""

from __future__ import annotations

import json
from pathlib import Path

from ntq_jax import artifacts
from ntq_jax.experiment.formatting import (
    fixed,
    interval,
    model_key,
    num,
    p_value,
    root_label,
    signed,
    stale_page,
)
from ntq_jax.experiment.quantities import Seeds, q_diff
from ntq_jax.experiment.summaries import load_summaries, main_runs
from ntq_jax.experiment.verdicts import ALPHA, verdict
from ntq_jax.multiplicity import holm
from ntq_jax.seed_effects import combine

__all__ = ["DOC_NAME", "TASK", "is_panda_root", "render", "write", "check"]

DOC_NAME = "REPRODUCTION.md"
TASK = "panda"
MEMBERS = ("PNet_0", "PNet_1", "PNet_2", "PNet_3")
KINDS = ("uniform", "nontrivial")
#: The peers of the problems table, in column order, and what a cell says without them.
PEER_COLUMNS = (("rrtconnect", "not installed"), ("vamp", "not built"))
_KIND = {"uniform": "uniform", "nontrivial": "non-trivial"}


def is_panda_root(root) -> bool:
    """Whether ``root`` holds summaries of the Panda task (``<root>/panda/``)."""
    return (Path(root) / TASK).is_dir()


def _scenes(summaries) -> list[str]:
    return sorted(main_runs(summaries))


def _seeds_of(summaries, env: str) -> list[int]:
    return sorted({int(s.get("train_seed") or 0) for s in summaries if s.get("env") == env})


def _verdict_rows(seeds: Seeds, envs: list[str], kind: str) -> list[str]:
    q = q_diff("PNet_3", "PNet_0", kind)
    ests = [(env, seeds.estimate(env, q)) for env in envs]
    ests = [(env, e) for env, e in ests if e is not None]
    if len(ests) > 1:
        ests.append((f"{len(ests)} scenes, pooled", combine([e for _, e in ests])))
    adj = holm([e.p() for _, e in ests]) if ests else []
    out = [
        "| map | seeds | PNet_3 - PNet_0 | 95% interval (seeds random) | between-seed sd "
        "| p | Holm p | verdict |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for (env, e), pa in zip(ests, adj):
        sign = 1 if e.estimate > 0 else -1 if e.estimate < 0 else 0
        sd = fixed(e.spread) if num(e.spread) else "(one seed)"
        note = "" if e.seed_aware else " (test queries only)"
        out.append(
            f"| {env} | {e.seeds} | {signed(e.estimate)} | {interval(e.ci()).strip()}{note} | {sd} "
            f"| {p_value(e.p())} | {p_value(pa)} | {verdict(sign, pa)} |"
        )
    if not ests:
        out.append("| (no summary yet) | | | | | | | |")
    return out + [""]


def _section_verdict(summaries) -> list[str]:
    seeds, envs = Seeds(summaries), _scenes(summaries)
    out = ["## The verdict at 7 DoF", ""]
    out += [
        "PNet_3 (non-trivial, pruned data) minus PNet_0 (uniform data) in success ratio on "
        "the same 500 non-trivial test queries, the mean over the training seeds with the "
        "seed a random effect (the interval and p of `results/paper/REPRODUCTION.md`), "
        f"Holm-adjusted over this table's rows; the verdict on the adjusted p at {ALPHA}.",
        "",
    ]
    out += _verdict_rows(seeds, envs, "nontrivial")
    out += ["On uniform test queries:", ""] + _verdict_rows(seeds, envs, "uniform")
    return out


def _cell(seeds: Seeds, env: str, model: str, kind: str, field: str) -> str:
    vals = []
    for s in seeds.runs.get(env, []):
        for r in s.get("rows", []):
            if (r["model"], r["query_kind"], r.get("steer")) == (model, kind, True):
                if num(r.get(field)):
                    vals.append(float(r[field]))
    if not vals:
        return ""
    mean = sum(vals) / len(vals)
    return (
        fixed(mean) if len(vals) == 1 else f"{fixed(mean)} [{fixed(min(vals))}, {fixed(max(vals))}]"
    )


def _models(summaries, env: str) -> list[str]:
    names = {
        r["model"]
        for s in summaries
        if s.get("env") == env
        for r in s.get("rows", [])
        if r.get("steer") is True
    }
    extra = sorted((n for n in names if n not in MEMBERS), key=model_key)
    return [m for m in MEMBERS if m in names] + extra


def _section_tables(summaries) -> list[str]:
    seeds = Seeds(summaries)
    out = ["## Success and cost per PNet", ""]
    out += [
        "Success ratio (a path proven collision-free, `eval.motion_check`) and cost ratio "
        "(neural / reference planner, on the queries both solved), with steerTo; the mean "
        "over the training seeds, [min, max] over them.",
        "",
    ]
    for env in _scenes(summaries):
        out += [f"### {env} (training seeds {_seeds_of(summaries, env)})", ""]
        out += [
            "| model | success, uniform | success, non-trivial | cost ratio, uniform "
            "| cost ratio, non-trivial |",
            "|---|---|---|---|---|",
        ]
        for m in _models(summaries, env):
            cells = [_cell(seeds, env, m, k, "success_ratio") for k in KINDS]
            cells += [_cell(seeds, env, m, k, "cost_ratio") for k in KINDS]
            out.append(f"| {m} | " + " | ".join(cells) + " |")
        out.append("")
    return out


def _ms(seconds) -> str:
    """Seconds as milliseconds with two decimals (VAMP's solve times are a fraction of one)."""
    return fixed(seconds * 1e3 if num(seconds) else seconds, 2)


def _problems(root: Path, summary: dict) -> dict | None:
    path = root / Path(summary["_path"]).parent / "problems.json"
    return json.loads(path.read_text(encoding="utf-8")) if path.is_file() else None


def _section_problems(root: Path, summaries) -> list[str]:
    out = ["## MotionBenchMaker's own problems", ""]
    out += [
        "The PNets are trained on one problem's world; MotionBenchMaker's 100 problems of "
        "the scene place its obstacles at other poses with their own start and goal. Solved "
        "= a path proven free in the problem's own world (the PNets, best-of-4: each "
        "problem's cheapest success of the four); the peers plan on the discretised check "
        "(their own kind): OMPL's RRT-Connect with simplification at "
        "`planner.eval_time_budget` seconds, VAMP's RRT-Connect with simplification (where "
        "VAMP is built) to its own iteration limit; `certified` counts their paths that also "
        "pass the certified check; `ms` are median milliseconds per problem (the PNets': "
        "all four planning it in one batch). Fractions of the valid problems.",
        "",
        "| map | seed | valid | PNet_0 | PNet_1 | PNet_2 | PNet_3 | best-of-4 | PNets ms "
        "| RRT-Connect | certified | RRT-Connect ms | VAMP | certified | VAMP ms |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    rows = 0
    for s in summaries:
        got = _problems(root, s)
        if got is None:
            continue
        rows += 1
        ms = got["models"]
        cells = [fixed(ms[m]["ratio"]) if m in ms else "" for m in MEMBERS]
        best = next((v for k, v in ms.items() if k.startswith("PNet_best-of")), None)
        pc = []
        for name, missing in PEER_COLUMNS:
            peer = got["peers"].get(name)
            pc += (
                [fixed(peer["solved"]["ratio"]), fixed(peer["certified"]["ratio"])]
                + [_ms(peer["median_solve_seconds"])]
                if peer
                else [missing, "", ""]
            )
        out.append(
            f"| {s['env']} | {s.get('train_seed') or 0} | {got['valid']} | "
            + " | ".join(cells)
            + f" | {fixed(best['ratio']) if best else ''} | {_ms(got['neural_median_seconds'])} | "
            + " | ".join(pc)
            + " |"
        )
    if not rows:
        out.append("| (no problems.json yet) |" + " |" * 14)
    return out + [""]


def _section_data(summaries) -> list[str]:
    out = ["## Data and time", ""]
    out += [
        "| map | seed | gamma_nt | D0 states / path | D3 samples | data s | train s | eval s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for s in summaries:
        rows = s.get("rows") or [{}]
        ds, t = s.get("datasets") or {}, s.get("timings") or {}
        d0, d3 = ds.get("D0") or {}, ds.get("D3") or {}
        out.append(
            f"| {s['env']} | {s.get('train_seed') or 0} | {fixed(rows[0].get('gamma_nt'))} | "
            f"{fixed(d0.get('states_per_path'), 2)} | {d3.get('samples', '')} | "
            f"{fixed(t.get('data'), 1)} | {fixed(t.get('train'), 1)} | {fixed(t.get('eval'), 1)} |"
        )
    return out + [""]


def render(root) -> str:
    """The whole page of the Panda summaries under ``root`` (deterministic)."""
    root = Path(root)
    summaries = [s for s in load_summaries(root) if s.get("task") == TASK]
    commands = sorted({s.get("command", "") for s in summaries if s.get("command")})
    lines = [
        "# Beyond the paper: a 7-DoF arm",
        "",
        "The paper's experiment (non-trivial query sampling, D0-D3, four PNets, the neural "
        "planner) on the Franka Panda in MotionBenchMaker's 3-D scenes, one step beyond the "
        "paper's planar 6-link arm. Made from the summaries in this folder by "
        f"`python scripts/reproduce.py --report-only --results {root_label(root)}` "
        "(`ntq_jax.experiment.panda_page`); the configuration and the reasons for every "
        "choice the paper leaves open are in `configs/panda.yaml`.",
        "",
        f"Cells: {len(summaries)} (scene x training seed). Commands: "
        + ("; ".join(f"`{c}`" for c in commands) or "none yet")
        + ".",
        "",
    ]
    lines += _section_verdict(summaries)
    lines += _section_tables(summaries)
    lines += _section_problems(root, summaries)
    lines += _section_data(summaries)
    return "\n".join(lines).rstrip("\n") + "\n"


def write(root) -> Path:
    """Writes ``<root>/REPRODUCTION.md`` (atomically) and returns its path."""
    return artifacts.write_text(Path(root) / DOC_NAME, render(root))


def check(root) -> str | None:
    """None if ``<root>/REPRODUCTION.md`` is what :func:`render` gives, else why not."""
    return stale_page(Path(root) / DOC_NAME, render(root), root)
