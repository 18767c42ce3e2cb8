"""The section "Seed variance" of ``REPRODUCTION.md``: every number over a map's training seeds.

A map's runs are its training seeds (the main run and ``seeds/train_seed_<k>``: the same
data, another training seed). :func:`seed_variance` gives the mean and range over them
of every row (success, cost ratio), :func:`seed_variance_diffs` of every paired success
difference (with how many seeds reach McNemar p < 0.05), and :func:`section` renders
both for each map. Data only (the summaries' dicts); both functions are also importable
from :mod:`ntq_jax.experiment.reproduction`. The verdicts' test over the same seeds:
:mod:`ntq_jax.experiment.quantities`.
"""

from __future__ import annotations

from ntq_jax.experiment.formatting import fixed, kind_name, model_key, num, signed
from ntq_jax.experiment.paper import KINDS, MAPS
from ntq_jax.experiment.summaries import is_seed_run
from ntq_jax.experiment.verdicts import ALPHA

__all__ = ["seed_variance", "seed_variance_diffs", "section"]


def _seed_runs(summaries, env: str) -> list[dict]:
    """The runs of ``env``, one per train seed (the main run first, as loaded)."""
    runs, seen = [], set()
    for s in summaries:
        if s.get("env") == env and s.get("train_seed") not in seen:
            seen.add(s.get("train_seed"))
            runs.append(s)
    return runs


def seed_variance(summaries, env: str) -> list[dict]:
    """Mean and range over the training seeds of ``env`` (main run and ``seeds/*``; one
    summary per train seed, the main run first): one dict per (steerTo, model, kind) with
    ``seeds``, ``success_mean``/``min``/``max`` and ``cost_mean``/``min``/``max``."""
    runs = _seed_runs(summaries, env)
    cells: dict = {}
    for s in runs:
        for r in s.get("rows", []):
            cells.setdefault(
                (
                    not bool(r.get("steer", True)),
                    model_key(r["model"]),
                    KINDS.index(r["query_kind"]) if r["query_kind"] in KINDS else 9,
                    r["model"],
                    r["query_kind"],
                    bool(r.get("steer", True)),
                ),
                [],
            ).append((s.get("train_seed"), r))
    out = []
    for key in sorted(cells):
        got = cells[key]
        sr = [r["success_ratio"] for _, r in got]
        cr = [r["cost_ratio"] for _, r in got if num(r.get("cost_ratio"))]
        out.append(
            {
                "model": key[3],
                "query_kind": key[4],
                "steer": key[5],
                "seeds": sorted((k for k, _ in got), key=str),
                "success_mean": sum(sr) / len(sr),
                "success_min": min(sr),
                "success_max": max(sr),
                "cost_mean": sum(cr) / len(cr) if cr else None,
                "cost_min": min(cr) if cr else None,
                "cost_max": max(cr) if cr else None,
            }
        )
    return out


def seed_variance_diffs(summaries, env: str) -> list[dict]:
    """Mean and range over the training seeds of ``env`` of every paired success difference
    (model - baseline): one dict per (steerTo, model, baseline, kind) with ``seeds``,
    ``diff_mean``/``min``/``max`` and ``significant`` (seeds with McNemar p < ALPHA)."""
    cells: dict = {}
    for s in _seed_runs(summaries, env):
        for c in s.get("comparisons", []):
            kind = c["query_kind"]
            key = (
                not bool(c.get("steer", True)),
                model_key(c["model"]),
                KINDS.index(kind) if kind in KINDS else 9,
                c["model"],
                c["baseline"],
                kind,
                bool(c.get("steer", True)),
            )
            cells.setdefault(key, []).append((s.get("train_seed"), c))
    out = []
    for key in sorted(cells):
        got = cells[key]
        d = [c["success_diff"] for _, c in got]
        out.append(
            {
                "model": key[3],
                "baseline": key[4],
                "query_kind": key[5],
                "steer": key[6],
                "seeds": sorted((k for k, _ in got), key=str),
                "diff_mean": sum(d) / len(d),
                "diff_min": min(d),
                "diff_max": max(d),
                "significant": sum(
                    num(c.get("mcnemar_p")) and c["mcnemar_p"] < ALPHA for _, c in got
                ),
            }
        )
    return out


def section(summaries) -> list[str]:
    """The section "Seed variance": per map with seed runs, :func:`seed_variance` and
    :func:`seed_variance_diffs` as two tables."""
    out = [
        "## Seed variance",
        "",
        "Same data, different training seeds (the main run and `seeds/train_seed_<k>`): mean "
        "and range [min, max] over the seeds found.",
        "",
    ]
    with_seeds = {s.get("env") for s in summaries if is_seed_run(s)}
    envs = [e for e in MAPS if e in with_seeds] + sorted(with_seeds - set(MAPS), key=str)
    for env in envs:
        stats = seed_variance(summaries, env)
        out += [f"### {env}", ""]
        if not stats:
            out += ["Not run yet.", ""]
            continue
        seeds = sorted({str(k) for st in stats for k in st["seeds"]})
        out += [
            f"Training seeds found: {', '.join(seeds)}.",
            "",
            "| Model | steerTo | kind | seeds | success mean | range | cost ratio mean | range |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for st in stats:
            out.append(
                f"| {st['model']} | {'yes' if st['steer'] else 'no'} | "
                f"{kind_name(st['query_kind'])} | {len(st['seeds'])} | "
                f"{fixed(st['success_mean'])} | [{fixed(st['success_min'])}, "
                f"{fixed(st['success_max'])}] | {fixed(st['cost_mean'])} | "
                f"[{fixed(st['cost_min'])}, {fixed(st['cost_max'])}] |"
            )
        diffs = seed_variance_diffs(summaries, env)
        if diffs:
            out += [
                "",
                "Paired success differences over the seeds (an ensemble row's baseline is "
                "each seed's best member; another best member is another line):",
                "",
                "| Model | vs | steerTo | kind | seeds | diff mean | range | "
                "seeds with McNemar p < 0.05 |",
                "|---|---|---|---|---|---|---|---|",
            ]
            for d in diffs:
                out.append(
                    f"| {d['model']} | {d['baseline']} | {'yes' if d['steer'] else 'no'} | "
                    f"{kind_name(d['query_kind'])} | {len(d['seeds'])} | "
                    f"{signed(d['diff_mean'])} | [{signed(d['diff_min'])}, "
                    f"{signed(d['diff_max'])}] | {d['significant']} |"
                )
        out.append("")
    return out
