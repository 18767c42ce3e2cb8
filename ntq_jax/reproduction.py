"""The paper's Tables I-IV beside ours: ``results/paper/REPRODUCTION.md`` from committed summaries.

The paper reproduced here is

    Sagar Suhas Joshi and Panagiotis Tsiotras, "Non-Trivial Query Sampling For
    Efficient Learning To Plan" (Georgia Institute of Technology).

Its numbers are transcribed in :data:`PAPER` (Tables I-IV: per environment
gamma_nt, and per model PNet_0..PNet_3 the success ratio and cost ratio on
uniform and on non-trivial test queries) and its experiment sizes in
:data:`PAPER_K_TRAIN`, :data:`PAPER_K_TEST` and :data:`PAPER_PADDING` (each with
the sentence of Section V it comes from).

Input: ``scripts/reproduce.py`` runs the pipeline one map at a time at the paper's
sizes and writes one folder per map, ``<root>/<task>/<map>/summary.json`` (task
``point``, ``rigid`` or ``nlink``; map like ``point_0``), and for the
seed-variance maps (:data:`SEED_MAPS`) the same schema under
``<root>/<task>/<map>/seeds/train_seed_<k>/summary.json`` (same data, another
training seed). A summary holds ``task``, ``env``, ``train_seed``, the resolved
``config``, the environment's data ``padding``, the result ``rows`` and paired
``comparisons`` of that map exactly as in a run's ``results.json``, the
``fingerprints`` of its datasets and models, per-stage ``timings`` and the
``command`` that made it.

Functions (pure, data only; this module computes nothing with JAX):

* :func:`load_summaries` reads every summary under a root, sorted by task, map
  (the paper's order), main run before seed runs, train seed.
* :func:`check_summary` lists what makes a summary not a paper-size run
  (K_train, K_test, padding, datasets D0..D3, fingerprints, timings, rows);
  empty when fine. :func:`check_seed_runs` checks that each seed run has its
  folder's train seed and the main run's dataset fingerprints (same data).
* :func:`claims` checks the trend claims of the paper's Results section, each
  one line with a verdict and the numbers (see "Claims" and "Verdicts" below).
* :func:`seed_variance` and :func:`seed_variance_diffs`: mean and range over a
  map's training seeds of every row (success, cost ratio) and of every paired
  success difference (with how many seeds reach p < 0.05).
* :func:`render` turns a root into the whole Markdown document: how it was
  made, coverage (which of the 11 maps and of Table III are present, which are
  missing), Tables I-IV (ours with the 95% interval next to the paper's; the
  ensemble rows, ours only; the paired differences PNet_1/2/3 - PNet_0 and
  ensemble - best member with their 95% interval and McNemar p; the reference
  planner and time per query), the time per stage and map, the seed variance
  (mean and range over the training seeds found for a map), and the claims.
  The output depends only on the summaries (no clock, fixed float formats).
* :func:`write` writes ``<root>/REPRODUCTION.md`` atomically.

Command line: ``python -m ntq_jax.reproduction [root]`` (default ``results/paper``)
writes the document and prints its path; ``--check`` writes nothing and exits 1
with a one-line message if the file on disk differs from what :func:`render` gives.

Claims (the paper's words in quotes; "with steerTo" = Tables I, II, IV):

* "In most cases, PNet_2 and PNet_3 outperform PNet_0": PNet_3 >= PNet_0 on
  non-trivial queries per map and pooled per task, PNet_2 and PNet_3 >= PNet_0
  pooled per task over both kinds;
* point: "all models perform well with a success rate of over 90%", per map
  (holds if every 95% interval is above 0.9, does not hold if one is below);
* rigid: "The PNet_3 model has the highest success ratio in all cases except
  one (Environment 3, Non-trivial Query)", per map and kind;
* n-link: "The success ratio over uniform queries is in the range of 0.9, 0.8
  and 0.7 for the case of 2, 4 and 6-link" (tested as falling from 2 to 4 to 6
  links), "about a 25% increase in the success ratio over PNet_0 for the 6-link
  (non-trivial queries) case" (holds if the paired 95% interval of our
  difference contains 0.25 x our PNet_0 success and the difference is
  significant, does not hold if the interval excludes it), and the gain on
  4 and 6 links larger than on 2 links ("much more evident");
* "The cost ratio is relatively lower for the rigid body and 6-link case":
  one-sided exact Mann-Whitney test of the maps' mean cost ratios;
* "The success ratio for all PNet models is naturally higher over uniform test
  queries", per task and model (Fisher, pooled over maps);
* "The success ratio also generally has an inverse relation with gamma_nt",
  per task, per query kind, and over all 11 maps;
* without steerTo (Table III): "the performance of PNet_3 is the worst" and
  "The PNet_0 model performs best on uniform queries in all environments" per
  map; "PNet_1 or PNet_2 show better performance over non-trivial queries in
  some cases" (holds if one does, significantly); "The success ratio of all
  PNet models is adversely affected", per model.

Verdicts (:func:`verdict`, level :data:`ALPHA` = 0.05): a claim that model A's
success ratio is at least model B's *holds* if our difference A - B has the
claimed sign and its p-value is below 0.05, *does not hold* if it has the
opposite sign with p below 0.05, and is *not resolvable at this K_test*
otherwise. The p-value is McNemar's exact test on the same test queries when the
summary has that paired comparison, else Fisher's exact test of the two success
counts (unpaired, conservative). A claim over a task pools the discordant pairs
of its maps into one exact McNemar test (each discordant pair is a fair coin
under the null hypothesis in every map, so the pooled count is exact too). A
claim made of several comparisons (e.g. "PNet_3 is the worst" = below each of
PNet_0..2) holds if every part holds and does not hold if any part does not
hold. "Success falls as gamma_nt rises" uses Kendall's tau between our gamma_nt
of the maps and their mean success over PNet_0..3, with the exact one-sided
p-value; with fewer than 4 maps no ordering reaches p < 0.05 (3 maps: 1/6), so
the claim is then not resolvable (too few maps). A claim whose maps are not run
yet says so.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from ntq_jax import artifacts
from ntq_jax.stats import mcnemar_exact

__all__ = ["PAPER", "PAPER_TABLES", "PAPER_K_TRAIN", "PAPER_K_TEST", "PAPER_PADDING",
           "PAPER_DATASETS", "MAPS", "SEED_MAPS", "ALPHA", "HOLDS", "FAILS", "UNRESOLVED",
           "NOT_RUN", "SummaryError", "load_summaries", "check_summary", "check_seed_runs", "verdict", "claims", "seed_variance",
           "seed_variance_diffs", "render", "write", "main"]

DOC_NAME = "REPRODUCTION.md"
TASKS = ("point", "rigid", "nlink")
KINDS = ("uniform", "nontrivial")
MEMBERS = ("PNet_0", "PNet_1", "PNet_2", "PNet_3")
ALPHA = 0.05  #: significance level of every verdict
HOLDS, FAILS, UNRESOLVED, NOT_RUN = ("holds", "does not hold", "not resolvable at this K_test",
                                     "not run")

# ---------------------------------------------------------------------------
# The paper
# ---------------------------------------------------------------------------

#: The 11 maps of the paper, in its order (Tables I, II/III and IV).
MAPS = ("point/0", "point/1", "point/2", "point/3", "rigid/0", "rigid/1", "rigid/2", "rigid/3",
        "nlink/2", "nlink/4", "nlink/6")
#: Maps run with three training seeds on the same data (issue 16, seed variance).
SEED_MAPS = ("rigid/0", "nlink/4", "point/0")

#: Queries per dataset (K_train), Section V of the paper:
#: point: "A total of $K_\mathrm{train}=3000$ number of queries were sampled for each dataset."
#: rigid: "A total of $K_\mathrm{train}=5000$ queries were considered to create each of the
#: four datasets"; n-link: "Four datasets ... were created for each of the $2,4$ and
#: $6$-link case by considering a total of $3000,4000$ and $5000$ queries respectively."
PAPER_K_TRAIN = {"point/0": 3000, "point/1": 3000, "point/2": 3000, "point/3": 3000,
                 "rigid/0": 5000, "rigid/1": 5000, "rigid/2": 5000, "rigid/3": 5000,
                 "nlink/2": 3000, "nlink/4": 4000, "nlink/6": 5000}
#: Test queries per kind (uniform and non-trivial), Section V: point: "solving
#: $K_\mathrm{test}=500$ number of unseen uniform and non-trivial queries"; rigid:
#: "evaluated on $K_\mathrm{test}=500$ unseen uniform and non-trivial queries"; n-link:
#: "solving $K_\mathrm{test}=500$ new queries with the neural planner".
PAPER_K_TEST = 500
#: Data-generation padding around the obstacles (relaxed to 0 at evaluation), Section V:
#: point: "A small padding of $0.8$ units around the obstacles was propagated during the
#: data generation step, and was relaxed during the final performance evaluation step.";
#: rigid: "An obstacle-padding of $0.4$ units was propagated during the data-generation
#: phase."; n-link: "These queries were solved using OMPL's BIT* planner with an padding
#: of $0.8$ units around the workspace obstacles."
PAPER_PADDING = {"point": 0.8, "rigid": 0.4, "nlink": 0.8}
#: The four datasets, Section V: "$\mathcal{D}_0 (p_\mathrm{nt}=0, \mathsf{pruneData}=
#: \mathsf{False})$, $\mathcal{D}_1 (p_\mathrm{nt}=0.5, ...False)$, $\mathcal{D}_2
#: (p_\mathrm{nt}=1.0, ...False)$, $\mathcal{D}_3 (p_\mathrm{nt}=1.0, ...True)$".
PAPER_DATASETS = ({"p_nt": 0.0, "prune": False}, {"p_nt": 0.5, "prune": False},
                  {"p_nt": 1.0, "prune": False}, {"p_nt": 1.0, "prune": True})

#: The paper's tables: id -> task, steerTo, caption, maps.
PAPER_TABLES = {
    "I": {"task": "point", "steer": True, "title": "Point robot planning",
          "envs": ("point/0", "point/1", "point/2", "point/3")},
    "II": {"task": "rigid", "steer": True, "title": "Rigid body planning",
           "envs": ("rigid/0", "rigid/1", "rigid/2", "rigid/3")},
    "III": {"task": "rigid", "steer": False, "title": "Rigid Body without steerTo",
            "envs": ("rigid/0", "rigid/1", "rigid/2", "rigid/3")},
    "IV": {"task": "nlink", "steer": True, "title": "n-link manipulator planning",
           "envs": ("nlink/2", "nlink/4", "nlink/6")},
}


def _t(su: float, cu: float, sn: float, cn: float) -> dict:
    """One model's line of a paper table: uniform (success, cost), non-trivial (success, cost)."""
    return {"uniform": {"success": su, "cost": cu}, "nontrivial": {"success": sn, "cost": cn}}


def _env(gamma: float, p0: dict, p1: dict, p2: dict, p3: dict) -> dict:
    return {"gamma_nt": gamma, "models": {"PNet_0": p0, "PNet_1": p1, "PNet_2": p2, "PNet_3": p3}}


#: The paper's Tables I-IV, exactly as printed (``PAPER[table][env]``: ``gamma_nt`` and
#: ``models[PNet_m][kind]`` with ``success`` and ``cost``). Printed as is, including the
#: 4-link PNet_3 uniform cost ratio 0.860 and its non-trivial success "0.82" (two digits).
PAPER = {
    "I": {
        "point/0": _env(0.311, _t(0.970, 1.004, 0.894, 1.006), _t(0.980, 1.002, 0.954, 1.007),
                        _t(0.974, 1.003, 0.918, 1.010), _t(0.980, 1.002, 0.930, 1.007)),
        "point/1": _env(0.402, _t(0.992, 1.031, 0.986, 1.075), _t(0.976, 1.029, 0.940, 1.064),
                        _t(0.986, 1.027, 0.966, 1.063), _t(0.992, 1.029, 0.988, 1.067)),
        "point/2": _env(0.414, _t(0.966, 1.051, 0.880, 1.117), _t(0.960, 1.051, 0.906, 1.125),
                        _t(0.950, 1.044, 0.916, 1.120), _t(0.962, 1.056, 0.900, 1.113)),
        "point/3": _env(0.628, _t(0.944, 1.056, 0.864, 1.156), _t(0.958, 1.069, 0.896, 1.167),
                        _t(0.956, 1.063, 0.898, 1.163), _t(0.974, 1.095, 0.912, 1.191)),
    },
    "II": {
        "rigid/0": _env(0.503, _t(0.828, 0.985, 0.656, 0.972), _t(0.842, 0.985, 0.622, 0.972),
                        _t(0.834, 0.979, 0.698, 0.960), _t(0.856, 0.978, 0.784, 0.958)),
        "rigid/1": _env(0.659, _t(0.788, 0.948, 0.714, 0.874), _t(0.784, 0.948, 0.686, 0.878),
                        _t(0.792, 0.971, 0.638, 0.889), _t(0.856, 0.950, 0.776, 0.865)),
        "rigid/2": _env(0.556, _t(0.862, 0.965, 0.770, 0.900), _t(0.898, 0.963, 0.776, 0.907),
                        _t(0.902, 0.963, 0.806, 0.908), _t(0.922, 0.970, 0.876, 0.912)),
        "rigid/3": _env(0.690, _t(0.722, 0.985, 0.606, 1.000), _t(0.714, 0.991, 0.660, 1.042),
                        _t(0.756, 0.994, 0.650, 0.996), _t(0.772, 0.981, 0.652, 1.006)),
    },
    "III": {
        "rigid/0": _env(0.503, _t(0.624, 0.982, 0.414, 0.957), _t(0.592, 0.983, 0.372, 0.979),
                        _t(0.564, 0.977, 0.392, 0.960), _t(0.228, 0.985, 0.212, 0.978)),
        "rigid/1": _env(0.659, _t(0.498, 0.971, 0.380, 0.936), _t(0.476, 0.965, 0.430, 0.923),
                        _t(0.456, 0.974, 0.372, 0.946), _t(0.266, 0.970, 0.208, 0.968)),
        "rigid/2": _env(0.556, _t(0.684, 0.943, 0.514, 0.872), _t(0.684, 0.944, 0.506, 0.889),
                        _t(0.630, 0.929, 0.550, 0.890), _t(0.284, 0.937, 0.270, 0.931)),
        "rigid/3": _env(0.690, _t(0.514, 0.986, 0.374, 0.990), _t(0.504, 0.996, 0.426, 1.005),
                        _t(0.502, 1.004, 0.396, 1.004), _t(0.302, 1.001, 0.196, 0.979)),
    },
    "IV": {
        "nlink/2": _env(0.225, _t(0.984, 1.002, 0.924, 1.061), _t(0.990, 1.004, 0.956, 1.060),
                        _t(0.984, 1.003, 0.962, 1.062), _t(0.988, 1.004, 0.972, 1.068)),
        "nlink/4": _env(0.366, _t(0.862, 1.005, 0.722, 1.003), _t(0.876, 0.997, 0.718, 0.991),
                        _t(0.890, 0.994, 0.772, 1.003), _t(0.928, 0.860, 0.82, 0.992)),
        "nlink/6": _env(0.608, _t(0.716, 0.982, 0.512, 0.972), _t(0.650, 0.980, 0.454, 0.966),
                        _t(0.712, 0.984, 0.528, 0.971), _t(0.776, 0.975, 0.644, 0.958)),
    },
}

# ---------------------------------------------------------------------------
# Summaries
# ---------------------------------------------------------------------------


def _task_of(env: str) -> str:
    return env.split("/", 1)[0]


def _map_key(env: str) -> tuple:
    return (MAPS.index(env), env) if env in MAPS else (len(MAPS), env)


def is_seed_run(summary: dict) -> bool:
    """Whether ``summary`` is a seed-variance run (under ``seeds/``), not a map's main run."""
    return "seeds" in Path(summary.get("_path", "")).parts


class SummaryError(ValueError):
    """A committed summary that cannot be read (the message names the file and the fix)."""


def load_summaries(root) -> list[dict]:
    """Every ``summary.json`` under ``root``: ``<task>/<map>/`` and ``<task>/<map>/seeds/*/``.

    Each summary gets ``_path``, its path relative to ``root`` (POSIX). Sorted by map (the
    paper's order, unknown maps after), main run before seed runs, then train seed and path.
    A missing root gives an empty list.

    Raises:
        SummaryError: a ``summary.json`` that is not valid JSON (or not an object).
    """
    root = Path(root)
    files = list(root.glob("*/*/summary.json")) + list(root.glob("*/*/seeds/*/summary.json"))
    out = []
    for f in files:
        try:
            s = json.loads(f.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
            raise SummaryError(f"{f}: not a readable summary ({type(e).__name__}: {e}); restore "
                               "it from git, or delete it and rerun the map with "
                               "scripts/reproduce.py") from None
        if not isinstance(s, dict):
            raise SummaryError(f"{f}: not a summary (a JSON object is expected); restore it "
                               "from git, or delete it and rerun the map")
        s["_path"] = f.relative_to(root).as_posix()
        out.append(s)
    return sorted(out, key=lambda s: (_map_key(s.get("env", "")), is_seed_run(s),
                                      s.get("train_seed", 0), s["_path"]))


def _k_train(config: dict, env: str):
    data = config.get("data", {})
    for o in data.get("per_env") or ():
        if o.get("env") == env and o.get("k_train") is not None:
            return o["k_train"]
    return data.get("k_train")


def check_summary(summary: dict) -> list[str]:
    """What makes ``summary`` not a paper-size run of its map; empty when it is one.

    Checked: schema 1; a known map of its task; K_train (``config.data``, with its
    ``per_env`` override) = :data:`PAPER_K_TRAIN`; ``config.eval.k_test`` and every row's
    ``k_test`` = :data:`PAPER_K_TEST`; ``padding`` = :data:`PAPER_PADDING` of the task;
    datasets = :data:`PAPER_DATASETS`; a non-empty fingerprint for every dataset D0..D3
    and for the models; timings of the data, train and eval stages; rows of PNet_0..3 on
    both query kinds with steerTo; for a rigid main run, rows without steerTo (Table III).
    """
    out = []
    env = summary.get("env")
    if summary.get("schema") != 1:
        out.append(f"schema is {summary.get('schema')!r}, expected 1")
    if env not in PAPER_K_TRAIN:
        return out + [f"env {env!r} is not one of the paper's maps"]
    task = _task_of(env)
    if summary.get("task") != task:
        out.append(f"task {summary.get('task')!r} does not match env {env}")
    config = summary.get("config") or {}
    kt = _k_train(config, env)
    if kt != PAPER_K_TRAIN[env]:
        out.append(f"K_train is {kt}, the paper's is {PAPER_K_TRAIN[env]}")
    k_test = config.get("eval", {}).get("k_test")
    if k_test != PAPER_K_TEST:
        out.append(f"K_test is {k_test}, the paper's is {PAPER_K_TEST}")
    pad = summary.get("padding")
    if not isinstance(pad, (int, float)) or abs(pad - PAPER_PADDING[task]) > 1e-9:
        out.append(f"padding is {pad}, the paper's is {PAPER_PADDING[task]}")
    ds = [{"p_nt": float(d.get("p_nt", -1)), "prune": bool(d.get("prune"))}
          for d in config.get("data", {}).get("datasets") or ()]
    if ds != list(PAPER_DATASETS):
        out.append(f"datasets are {ds}, the paper's are D0..D3 {list(PAPER_DATASETS)}")
    fp = summary.get("fingerprints") or {}
    fd = fp.get("datasets") or {}
    missing = [f"D{i}" for i in range(len(PAPER_DATASETS)) if not fd.get(f"D{i}")]
    if missing:
        out.append(f"dataset fingerprints missing: {', '.join(missing)}")
    if not fp.get("models"):
        out.append("model fingerprint missing")
    tm = summary.get("timings") or {}
    if any(not isinstance(tm.get(k), (int, float)) for k in ("data", "train", "eval")):
        out.append("timings of data/train/eval missing")
    rows = summary.get("rows") or []
    bad_k = sorted({r.get("k_test") for r in rows if r.get("k_test") != PAPER_K_TEST}, key=str)
    if bad_k:
        out.append(f"rows with k_test {bad_k}, the paper's is {PAPER_K_TEST}")
    have = {(r.get("model"), r.get("query_kind"), r.get("steer")) for r in rows}
    need = [(m, k, True) for m in MEMBERS for k in KINDS]
    if task == "rigid" and not is_seed_run(summary):
        need += [(m, k, False) for m in MEMBERS for k in KINDS]
    lack = [f"{m} {k}{'' if s else ' without steerTo'}" for m, k, s in need if (m, k, s) not in have]
    if lack:
        out.append(f"rows missing: {', '.join(lack)}")
    return out


def check_seed_runs(summaries) -> list[str]:
    """What is wrong with the seed-variance runs of ``summaries``; empty when fine.

    A seed run (``<task>/<map>/seeds/train_seed_<k>/``) must have ``train_seed`` k, a
    main run of its map, and the main run's dataset fingerprints (same data, another
    training seed).
    """
    out = []
    main = _main_runs(summaries)
    for s in summaries:
        if not is_seed_run(s):
            continue
        path, env = s.get("_path", "?"), s.get("env")
        folder = Path(path).parent.name
        if folder != f"train_seed_{s.get('train_seed')}":
            out.append(f"{path}: train_seed {s.get('train_seed')!r} but folder {folder}")
        m = main.get(env)
        if m is None:
            out.append(f"{path}: no main run of {env}")
            continue
        fd = (s.get("fingerprints") or {}).get("datasets")
        if fd != (m.get("fingerprints") or {}).get("datasets"):
            out.append(f"{path}: dataset fingerprints differ from the main run of {env}")
    return out


def _main_runs(summaries) -> dict:
    """``{env: summary}`` of the main runs (first one per map)."""
    out = {}
    for s in summaries:
        if not is_seed_run(s):
            out.setdefault(s.get("env"), s)
    return out


def _cell(summary, steer: bool) -> dict:
    """``{(model, kind): row}`` of ``summary`` with steerTo ``steer``."""
    if summary is None:
        return {}
    return {(r["model"], r["query_kind"]): r for r in summary.get("rows", [])
            if bool(r.get("steer", True)) == steer}


# ---------------------------------------------------------------------------
# Formatting
# ---------------------------------------------------------------------------


def _num(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _f(x, nd: int = 3) -> str:
    return f"{x:.{nd}f}" if _num(x) else "-"


def _ci(lo_hi, nd: int = 3) -> str:
    if not lo_hi or not all(_num(v) for v in lo_hi):
        return ""
    return f" [{lo_hi[0]:.{nd}f}, {lo_hi[1]:.{nd}f}]"


def _signed(x, nd: int = 3) -> str:
    return f"{x:+.{nd}f}" if _num(x) else "-"


def _p(p) -> str:
    if not _num(p):
        return "-"
    return "<0.001" if p < 1e-3 else f"{p:.3f}"


def _model_key(name: str) -> tuple:
    """PNet_0..PNet_m by index, then PNet_ens, PNet_best-of-N, PNet_cascade, then by name."""
    tail = name.split("_", 1)[-1]
    if tail.isdigit():
        return (0, int(tail), name)
    return ({"ens": 1, "cascade": 3}.get(tail, 2 if tail.startswith("best-of-") else 4), 0, name)


def _kind_name(kind: str) -> str:
    return {"uniform": "uniform", "nontrivial": "non-trivial"}.get(kind, kind)


# ---------------------------------------------------------------------------
# Tests of one comparison, verdicts
# ---------------------------------------------------------------------------


def verdict(diff, p, sign: int = 1, alpha: float = ALPHA) -> str:
    """The verdict on the claim ``sign * diff >= 0``: holds if ``sign * diff > 0`` with
    ``p < alpha``, does not hold if ``sign * diff < 0`` with ``p < alpha``, else not resolvable."""
    if not _num(diff) or not _num(p):
        return NOT_RUN
    if p < alpha and sign * diff > 0:
        return HOLDS
    if p < alpha and sign * diff < 0:
        return FAILS
    return UNRESOLVED


def _combine(verdicts) -> str:
    """A claim made of parts: does not hold if any part does not, holds if all hold."""
    v = list(verdicts)
    if not v or NOT_RUN in v:
        return NOT_RUN
    if FAILS in v:
        return FAILS
    return HOLDS if all(x == HOLDS for x in v) else UNRESOLVED


def _fisher(sa: int, na: int, sb: int, nb: int) -> float:
    from scipy.stats import fisher_exact
    return float(fisher_exact([[sa, na - sa], [sb, nb - sb]]).pvalue)


def compare(summary, a: str, b: str, kind: str, steer: bool = True) -> dict | None:
    """Success of model ``a`` minus model ``b`` on ``kind`` queries of one map.

    The paired comparison of the summary if it has one (either direction): ``diff``,
    ``ci`` (Newcombe's 95%), McNemar's ``p``, discordant counts ``only_a``/``only_b``, ``n``;
    else Fisher's exact test of the two rows' success counts (``paired`` False). None if a
    row is missing.
    """
    if summary is None:
        return None
    for c in summary.get("comparisons", []):
        if (c.get("query_kind") != kind or bool(c.get("steer", True)) != steer):
            continue
        if (c.get("model"), c.get("baseline")) == (a, b):
            return {"diff": c["success_diff"], "ci": c.get("success_diff_ci95"),
                    "p": c["mcnemar_p"], "only_a": c["only_a"], "only_b": c["only_b"],
                    "n": c["n"], "paired": True}
        if (c.get("model"), c.get("baseline")) == (b, a):
            ci = c.get("success_diff_ci95")
            return {"diff": -c["success_diff"], "ci": None if not ci else [-ci[1], -ci[0]],
                    "p": c["mcnemar_p"], "only_a": c["only_b"], "only_b": c["only_a"],
                    "n": c["n"], "paired": True}
    cell = _cell(summary, steer)
    ra, rb = cell.get((a, kind)), cell.get((b, kind))
    if ra is None or rb is None:
        return None
    return {"diff": ra["success_ratio"] - rb["success_ratio"], "ci": None,
            "p": _fisher(ra["successes"], ra["k_test"], rb["successes"], rb["k_test"]),
            "paired": False}


def _pooled(tests) -> dict | None:
    """The maps' paired tests pooled: discordant pairs summed, one exact McNemar test."""
    if not tests or any(t is None or not t["paired"] for t in tests):
        return None
    b = sum(t["only_a"] for t in tests)
    c = sum(t["only_b"] for t in tests)
    n = sum(t["n"] for t in tests)
    return {"diff": (b - c) / n, "p": mcnemar_exact(b, c), "only_a": b, "only_b": c, "n": n,
            "paired": True}


def _test_text(t) -> str:
    if t is None:
        return "-"
    how = "McNemar" if t["paired"] else "Fisher"
    return f"{_signed(t['diff'])}{_ci(t.get('ci'))}, {how} p {_p(t['p'])}"


def _claim(table: str, claim: str, scope: str, v: str, evidence: str, paper: str) -> dict:
    return {"table": table, "claim": claim, "scope": scope, "verdict": v, "evidence": evidence,
            "paper": paper}


def _paper_s(table: str, env: str, model: str, kind: str):
    return PAPER[table][env]["models"][model][kind]["success"]


def _row_s(summary, model, kind, steer=True):
    r = _cell(summary, steer).get((model, kind))
    return None if r is None else r["success_ratio"]


# ---------------------------------------------------------------------------
# Claims
# ---------------------------------------------------------------------------


def _claims_pnet_vs_pnet0(main, table) -> list[dict]:
    """PNet_3 >= PNet_0 on non-trivial queries per map and per task; PNet_2 and PNet_3 >=
    PNet_0 pooled over the task's maps and both kinds ("In most cases, PNet_2 and PNet_3
    outperform PNet_0 in terms of success ratio")."""
    spec = PAPER_TABLES[table]
    out, tests = [], []
    text = "PNet_3 >= PNet_0 in success on non-trivial queries"
    for env in spec["envs"]:
        s = main.get(env)
        t = compare(s, "PNet_3", "PNet_0", "nontrivial", spec["steer"])
        tests.append(t)
        pd = _paper_s(table, env, "PNet_3", "nontrivial") - _paper_s(table, env, "PNet_0",
                                                                      "nontrivial")
        ev = ("not run" if t is None else f"{_f(_row_s(s, 'PNet_3', 'nontrivial'))} vs "
              f"{_f(_row_s(s, 'PNet_0', 'nontrivial'))}: {_test_text(t)}")
        out.append(_claim(table, text, env, NOT_RUN if t is None else verdict(t["diff"], t["p"]),
                          ev, f"{_f(_paper_s(table, env, 'PNet_3', 'nontrivial'))} vs "
                              f"{_f(_paper_s(table, env, 'PNet_0', 'nontrivial'))} "
                              f"({_signed(pd)})"))
    out.append(_pooled_claim(table, text, tests, "nontrivial"))
    for model in ("PNet_2", "PNet_3"):
        tests = [compare(main.get(env), model, "PNet_0", kind, spec["steer"])
                 for env in spec["envs"] for kind in KINDS]
        out.append(_pooled_claim(table, f"{model} >= PNet_0 in success (both kinds)", tests,
                                 None, model))
    return out


def _pooled_claim(table, text, tests, kind, model="PNet_3") -> dict:
    spec = PAPER_TABLES[table]
    t = _pooled(tests)
    kinds = KINDS if kind is None else (kind,)
    pd = [_paper_s(table, e, model, k) - _paper_s(table, e, "PNet_0", k)
          for e in spec["envs"] for k in kinds]
    scope = f"{spec['task']}, pooled over {len(spec['envs'])} maps"
    paper = (f"mean diff {_signed(sum(pd) / len(pd))}; {model} ahead in "
             f"{sum(d > 0 for d in pd)} of {len(pd)}")
    if t is None:
        n_run = sum(x is not None for x in tests)
        ev = (f"not run ({n_run} of {len(tests)} map-kind cells present)" if n_run < len(tests)
              else "no paired comparison to pool")
        return _claim(table, text, scope, NOT_RUN, ev, paper)
    ev = (f"mean diff {_signed(t['diff'])}, discordant {t['only_a']} / {t['only_b']} of "
          f"{t['n']}, McNemar p {_p(t['p'])}")
    return _claim(table, text, scope, verdict(t["diff"], t["p"]), ev, paper)


def _claims_uniform_above_nt(main, table) -> list[dict]:
    """"The success ratio for all PNet models is naturally higher over uniform test queries
    rather than non-trivial test queries": per model, success pooled over the task's maps,
    uniform vs non-trivial (different query sets: Fisher's exact test)."""
    spec = PAPER_TABLES[table]
    parts, ev, paper = [], [], []
    for m in MEMBERS:
        rows = [_cell(main.get(e), spec["steer"]) for e in spec["envs"]]
        ru = [c.get((m, "uniform")) for c in rows]
        rn = [c.get((m, "nontrivial")) for c in rows]
        pu = [_paper_s(table, e, m, "uniform") - _paper_s(table, e, m, "nontrivial")
              for e in spec["envs"]]
        paper.append(f"{m} {sum(d > 0 for d in pu)}/{len(pu)} maps")
        if any(r is None for r in ru + rn):
            parts.append(NOT_RUN)
            continue
        su, nu = sum(r["successes"] for r in ru), sum(r["k_test"] for r in ru)
        sn, nn = sum(r["successes"] for r in rn), sum(r["k_test"] for r in rn)
        p = _fisher(su, nu, sn, nn)
        parts.append(verdict(su / nu - sn / nn, p))
        ev.append(f"{m} {su / nu:.3f} vs {sn / nn:.3f} (Fisher p {_p(p)})")
    v = _combine(parts)
    return [_claim(table, "success higher on uniform than on non-trivial queries, every model",
                   f"{spec['task']}, pooled over {len(spec['envs'])} maps", v,
                   "; ".join(ev) if v != NOT_RUN else "not run",
                   "uniform above in " + ", ".join(paper))]


def _kendall(x, y) -> tuple[float, float, float]:
    """Kendall's tau of ``x, y`` and its one-sided p-values (tau < 0, tau > 0); exact
    without ties."""
    from scipy.stats import kendalltau
    method = "exact" if len(set(x)) == len(x) and len(set(y)) == len(y) else "auto"
    lo = kendalltau(x, y, method=method, alternative="less")
    hi = kendalltau(x, y, method=method, alternative="greater")
    return float(lo.statistic), float(lo.pvalue), float(hi.pvalue)


def _gamma(summary, steer=True):
    r = _cell(summary, steer).get(("PNet_0", "uniform")) or next(
        iter(_cell(summary, steer).values()), None)
    return None if r is None else r.get("gamma_nt")


def _claims_gamma(main, tables, scope, label: str | None = None) -> list[dict]:
    """"The success ratio also generally has an inverse relation with gamma_nt": Kendall's
    tau between gamma_nt and the mean success over PNet_0..3, per query kind."""
    out = []
    for kind in KINDS:
        x, y, px, py = [], [], [], []
        for table in tables:
            spec = PAPER_TABLES[table]
            for env in spec["envs"]:
                px.append(PAPER[table][env]["gamma_nt"])
                py.append(sum(_paper_s(table, env, m, kind) for m in MEMBERS) / len(MEMBERS))
                c = _cell(main.get(env), spec["steer"])
                rs = [c.get((m, kind)) for m in MEMBERS]
                g = _gamma(main.get(env), spec["steer"])
                if all(r is not None for r in rs) and _num(g):
                    x.append(g)
                    y.append(sum(r["success_ratio"] for r in rs) / len(rs))
        ptau, pp, _ = _kendall(px, py)
        paper = f"tau {ptau:+.2f} over {len(px)} maps (one-sided p {_p(pp)})"
        text = f"success falls as gamma_nt rises ({_kind_name(kind)} queries, mean of PNet_0..3)"
        pts = ", ".join(f"{g:.3f}: {s:.3f}" for g, s in sorted(zip(x, y)))
        if len(x) < 4:
            v = NOT_RUN if not x else UNRESOLVED + f" (too few maps: {len(x)})"
            out.append(_claim(label or tables[0], text, scope, v, f"{len(x)} maps run" +
                              (f" (gamma_nt: success {pts})" if pts else ""), paper))
            continue
        tau, p_less, p_greater = _kendall(x, y)
        v = HOLDS if p_less < ALPHA else FAILS if p_greater < ALPHA else UNRESOLVED
        out.append(_claim(label or tables[0], text, scope, v,
                          f"Kendall tau {tau:+.2f} over {len(x)} maps, one-sided p {_p(p_less)} "
                          f"(gamma_nt: success {pts})", paper))
    return out


def _claims_rank(main, table, model, others, sign, kinds, text) -> list[dict]:
    """``model`` above (sign +1) or below (sign -1) each of ``others`` on each map and kind."""
    spec = PAPER_TABLES[table]
    out = []
    for env in spec["envs"]:
        for kind in kinds:
            s = main.get(env)
            tests = [compare(s, model, o, kind, spec["steer"]) for o in others]
            v = _combine(NOT_RUN if t is None else verdict(t["diff"], t["p"], sign)
                         for t in tests)
            ev = "not run" if s is None or any(t is None for t in tests) else "; ".join(
                f"vs {o} {_test_text(t)}" for o, t in zip(others, tests))
            ps = _paper_s(table, env, model, kind)
            paper = ", ".join(f"{m} {_f(_paper_s(table, env, m, kind))}"
                              for m in (model,) + tuple(others))
            ok = all(sign * (ps - _paper_s(table, env, o, kind)) >= 0 for o in others)
            out.append(_claim(table, text, f"{env}, {_kind_name(kind)}", v, ev,
                              paper + ("" if ok else " (not so in the paper)")))
    return out


def _claims_nosteer(main) -> list[dict]:
    """Table III: PNet_3 worst, PNet_0 best on uniform, PNet_1/2 better on non-trivial in some
    cases, and every model below its steerTo success."""
    out = _claims_rank(main, "III", "PNet_3", ("PNet_0", "PNet_1", "PNet_2"), -1, KINDS,
                       "without steerTo PNet_3 is the worst")
    out += _claims_rank(main, "III", "PNet_0", ("PNet_1", "PNet_2", "PNet_3"), 1, ("uniform",),
                        "without steerTo PNet_0 is the best on uniform queries")
    envs = PAPER_TABLES["III"]["envs"]
    tests = [(env, m, compare(main.get(env), m, "PNet_0", "nontrivial", False))
             for env in envs for m in ("PNet_1", "PNet_2")]
    vs = [NOT_RUN if t is None else verdict(t["diff"], t["p"]) for _, _, t in tests]
    v = (HOLDS if HOLDS in vs else NOT_RUN if NOT_RUN in vs
         else FAILS if all(x == FAILS for x in vs) else UNRESOLVED)
    ev = "; ".join(f"{e} {m} {_test_text(t)}" for e, m, t in tests if t is not None) or "not run"
    paper = "; ".join(f"{e} {m} {_signed(_paper_s('III', e, m, 'nontrivial') - _paper_s('III', e, 'PNet_0', 'nontrivial'))}"
                      for e, m, _ in tests)
    out.append(_claim("III", "without steerTo PNet_1 or PNet_2 beats PNet_0 on non-trivial "
                      "queries in some cases", "rigid, any map", v, ev, paper))
    for m in MEMBERS:
        pairs = [(_cell(main.get(e), True).get((m, k)), _cell(main.get(e), False).get((m, k)))
                 for e in envs for k in KINDS]
        pp = [_paper_s("II", e, m, k) - _paper_s("III", e, m, k) for e in envs for k in KINDS]
        paper = f"below in {sum(d > 0 for d in pp)}/{len(pp)} (mean {_signed(-sum(pp) / len(pp))})"
        text = "the success of every model falls without steerTo"
        if any(a is None or b is None for a, b in pairs):
            out.append(_claim("III", text, f"rigid, {m}, pooled", NOT_RUN, "not run", paper))
            continue
        sa, na = sum(a["successes"] for a, _ in pairs), sum(a["k_test"] for a, _ in pairs)
        sb, nb = sum(b["successes"] for _, b in pairs), sum(b["k_test"] for _, b in pairs)
        p = _fisher(sa, na, sb, nb)
        out.append(_claim("III", text, f"rigid, {m}, pooled over maps and kinds",
                          verdict(sb / nb - sa / na, p, -1),
                          f"{sb / nb:.3f} without vs {sa / na:.3f} with steerTo (Fisher p "
                          f"{_p(p)})", paper))
    return out


def _claims_point_90(main) -> list[dict]:
    """"For the case of point robot planning, all models perform well with a success rate of
    over 90%": holds if every 95% interval is above 0.9, does not hold if one is below."""
    out = []
    for env in PAPER_TABLES["I"]["envs"]:
        c = _cell(main.get(env), True)
        rows = [c.get((m, k)) for m in MEMBERS for k in KINDS]
        pmin = min(_paper_s("I", env, m, k) for m in MEMBERS for k in KINDS)
        paper = f"min {pmin:.3f}" + ("" if pmin > 0.9 else " (not so in the paper)")
        if any(r is None for r in rows):
            out.append(_claim("I", "every model succeeds on over 90% of queries", env, NOT_RUN,
                              "not run", paper))
            continue
        lo = min(r["success_ci95"][0] for r in rows)
        hi = min(r["success_ci95"][1] for r in rows)
        worst = min(rows, key=lambda r: r["success_ratio"])
        v = HOLDS if lo > 0.9 else FAILS if hi < 0.9 else UNRESOLVED
        out.append(_claim("I", "every model succeeds on over 90% of queries", env, v,
                          f"lowest {worst['model']} {_kind_name(worst['query_kind'])} "
                          f"{_f(worst['success_ratio'])}{_ci(worst['success_ci95'])}", paper))
    return out


def _claims_nlink(main) -> list[dict]:
    """Table IV: uniform success about 0.9, 0.8, 0.7 for 2, 4, 6 links (tested as falling
    with the number of links) and PNet_3 about 25% above PNet_0 on 6-link non-trivial."""
    out = []
    pooled, paper = [], []
    for env in PAPER_TABLES["IV"]["envs"]:
        c = _cell(main.get(env), True)
        rows = [c.get((m, "uniform")) for m in MEMBERS]
        paper.append(f"{env} {sum(_paper_s('IV', env, m, 'uniform') for m in MEMBERS) / 4:.3f}")
        pooled.append(None if any(r is None for r in rows) else
                      (sum(r["successes"] for r in rows), sum(r["k_test"] for r in rows)))
    text = ("uniform success about 0.9, 0.8, 0.7 for 2, 4, 6 links (falls with the number of "
            "links; mean of PNet_0..3)")
    if any(p is None for p in pooled):
        out.append(_claim("IV", text, "nlink", NOT_RUN, "not run", "; ".join(paper)))
    else:
        tests = [(pooled[i], pooled[i + 1], _fisher(*pooled[i], *pooled[i + 1])) for i in (0, 1)]
        v = _combine(verdict(a[0] / a[1] - b[0] / b[1], p) for a, b, p in tests)
        ev = "; ".join(f"{e} {s / n:.3f}" for e, (s, n) in zip(PAPER_TABLES["IV"]["envs"], pooled))
        ev += "; Fisher p 2 vs 4 links " + _p(tests[0][2]) + ", 4 vs 6 links " + _p(tests[1][2])
        out.append(_claim("IV", text, "nlink", v, ev, "; ".join(paper)))
    s = main.get("nlink/6")
    t = compare(s, "PNet_3", "PNet_0", "nontrivial", True)
    p0, p3 = _paper_s("IV", "nlink/6", "PNet_0", "nontrivial"), _paper_s("IV", "nlink/6", "PNet_3",
                                                                           "nontrivial")
    paper = f"{p3:.3f} vs {p0:.3f} ({p3 / p0 - 1:+.1%})"
    text = "PNet_3 about 25% above PNet_0 in success on non-trivial queries"
    s0 = _row_s(s, "PNet_0", "nontrivial")
    if t is None or not _num(s0) or s0 <= 0:
        out.append(_claim("IV", text, "nlink/6", NOT_RUN, "not run", paper))
        return out
    claimed = 0.25 * s0
    ci = t.get("ci")
    if ci and all(_num(x) for x in ci):
        inside = ci[0] <= claimed <= ci[1]
        v = (FAILS if not inside else HOLDS if verdict(t["diff"], t["p"]) == HOLDS
             else UNRESOLVED)
    else:
        v = UNRESOLVED
    side = ("" if v != FAILS else " (our gain is larger)" if t["diff"] > claimed
            else " (our gain is smaller)")
    out.append(_claim("IV", text, "nlink/6 (claimed diff = 0.25 x our PNet_0)", v,
                      f"{_f(_row_s(s, 'PNet_3', 'nontrivial'))} vs {_f(s0)} "
                      f"({t['diff'] / s0:+.1%}); claimed diff {claimed:+.3f}, ours "
                      f"{_test_text(t)}{side}", paper))
    return out


def _mean_cost(summary, steer=True):
    rs = [_cell(summary, steer).get((m, k)) for m in MEMBERS for k in KINDS]
    if summary is None or any(r is None or not _num(r.get("cost_ratio")) for r in rs):
        return None
    return sum(r["cost_ratio"] for r in rs) / len(rs)


def _paper_cost(table, env):
    ms = PAPER[table][env]["models"]
    return sum(ms[m][k]["cost"] for m in MEMBERS for k in KINDS) / (len(MEMBERS) * len(KINDS))


#: "The cost ratio is relatively lower for the rigid body and 6-link case compared to
#: others": the maps of the low group (table, env) and of the others.
_LOW_COST = tuple(("II", e) for e in PAPER_TABLES["II"]["envs"]) + (("IV", "nlink/6"),)
_OTHER_COST = tuple(("I", e) for e in PAPER_TABLES["I"]["envs"]) + (("IV", "nlink/2"),
                                                                    ("IV", "nlink/4"))


def _claims_cost(main) -> list[dict]:
    """Cost ratio lower for rigid body and 6-link than for the other maps: the maps' mean
    cost ratio (PNet_0..3, both kinds), one-sided exact Mann-Whitney test between the two
    groups of maps (all 11 needed)."""
    from scipy.stats import mannwhitneyu
    low = [_mean_cost(main.get(e)) for _, e in _LOW_COST]
    other = [_mean_cost(main.get(e)) for _, e in _OTHER_COST]
    pl, po = [_paper_cost(t, e) for t, e in _LOW_COST], [_paper_cost(t, e) for t, e in _OTHER_COST]
    paper = f"mean {sum(pl) / len(pl):.3f} vs {sum(po) / len(po):.3f}"
    text = "cost ratio lower for rigid body and 6-link than for the other maps"
    scope = "rigid/0-3 + nlink/6 vs point/0-3 + nlink/2, nlink/4"
    if any(x is None for x in low + other):
        n = sum(x is not None for x in low + other)
        return [_claim("I, II, IV", text, scope, NOT_RUN, f"{n} of 11 maps run", paper)]
    p_less = float(mannwhitneyu(low, other, alternative="less", method="exact").pvalue)
    p_greater = float(mannwhitneyu(low, other, alternative="greater", method="exact").pvalue)
    v = HOLDS if p_less < ALPHA else FAILS if p_greater < ALPHA else UNRESOLVED
    ev = (f"mean {sum(low) / len(low):.3f} vs {sum(other) / len(other):.3f}; "
          f"Mann-Whitney one-sided p {_p(p_less)}")
    return [_claim("I, II, IV", text, scope, v, ev, paper)]


def _claims_nlink_gain(main) -> list[dict]:
    """"For the relatively simpler 2-link planning case ... only small gains in the success
    ratio over non-trivial queries can be seen. However, the improvement in performance is
    much more evident for the higher dimensional 4 and 6-link cases": the gain PNet_3 -
    PNet_0 (non-trivial) of the 4- and of the 6-link arm each above the 2-link arm's; the
    maps are independent, so each difference of gains is a z-test with the standard
    errors of the gains read from their 95% intervals (half-width / 1.96)."""
    from scipy.stats import norm
    envs = PAPER_TABLES["IV"]["envs"]
    tests = [compare(main.get(e), "PNet_3", "PNet_0", "nontrivial", True) for e in envs]
    pd = [_paper_s("IV", e, "PNet_3", "nontrivial") - _paper_s("IV", e, "PNet_0", "nontrivial")
          for e in envs]
    paper = ", ".join(f"{e} {_signed(d)}" for e, d in zip(envs, pd))
    text = "PNet_3's gain over PNet_0 (non-trivial) larger for 4 and 6 links than for 2 links"
    if any(t is None for t in tests):
        return [_claim("IV", text, "nlink", NOT_RUN, "not run", paper)]
    if any(not t.get("ci") or not all(_num(x) for x in t["ci"]) for t in tests):
        return [_claim("IV", text, "nlink", UNRESOLVED, "no 95% interval of the gains", paper)]
    se = [(t["ci"][1] - t["ci"][0]) / (2 * 1.959963984540054) for t in tests]
    parts, ev = [], []
    for i in (1, 2):
        d = tests[i]["diff"] - tests[0]["diff"]
        s = math.hypot(se[i], se[0])
        p = 1.0 if s == 0 and d == 0 else 0.0 if s == 0 else float(2 * norm.sf(abs(d) / s))
        parts.append(verdict(d, p))
        ev.append(f"{envs[i]} minus {envs[0]} {_signed(d)} (z-test p {_p(p)})")
    gains = ", ".join(f"{e} {_signed(t['diff'])}" for e, t in zip(envs, tests))
    return [_claim("IV", text, "nlink", _combine(parts), f"gains {gains}; " + "; ".join(ev),
                   paper)]


def claims(summaries) -> list[dict]:
    """The paper's trend claims checked on ``summaries`` (main runs), one dict per line:
    ``table``, ``claim``, ``scope``, ``verdict`` (:data:`HOLDS`, :data:`FAILS`,
    :data:`UNRESOLVED` or :data:`NOT_RUN`), ``evidence`` (ours) and ``paper``."""
    main = _main_runs(summaries)
    out = []
    for table in ("I", "II", "IV"):
        out += _claims_pnet_vs_pnet0(main, table)
    out += _claims_point_90(main)
    out += _claims_rank(main, "II", "PNet_3", ("PNet_0", "PNet_1", "PNet_2"), 1, KINDS,
                        "with steerTo PNet_3 has the highest success (paper: all but rigid/3 "
                        "non-trivial)")
    out += _claims_nlink(main)
    out += _claims_nlink_gain(main)
    out += _claims_cost(main)
    for table in ("I", "II", "IV"):
        out += _claims_uniform_above_nt(main, table)
    for table in ("I", "II", "IV"):
        out += _claims_gamma(main, (table,), PAPER_TABLES[table]["task"])
    out += _claims_gamma(main, ("I", "II", "IV"), "all 11 maps with steerTo", "I, II, IV")
    out += _claims_nosteer(main)
    return out


# ---------------------------------------------------------------------------
# Seed variance
# ---------------------------------------------------------------------------


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
            cells.setdefault((not bool(r.get("steer", True)), _model_key(r["model"]),
                              KINDS.index(r["query_kind"]) if r["query_kind"] in KINDS else 9,
                              r["model"], r["query_kind"], bool(r.get("steer", True))),
                             []).append((s.get("train_seed"), r))
    out = []
    for key in sorted(cells):
        got = cells[key]
        sr = [r["success_ratio"] for _, r in got]
        cr = [r["cost_ratio"] for _, r in got if _num(r.get("cost_ratio"))]
        out.append({"model": key[3], "query_kind": key[4], "steer": key[5],
                    "seeds": sorted((k for k, _ in got), key=str),
                    "success_mean": sum(sr) / len(sr), "success_min": min(sr),
                    "success_max": max(sr),
                    "cost_mean": sum(cr) / len(cr) if cr else None,
                    "cost_min": min(cr) if cr else None, "cost_max": max(cr) if cr else None})
    return out


def seed_variance_diffs(summaries, env: str) -> list[dict]:
    """Mean and range over the training seeds of ``env`` of every paired success difference
    (model - baseline): one dict per (steerTo, model, baseline, kind) with ``seeds``,
    ``diff_mean``/``min``/``max`` and ``significant`` (seeds with McNemar p < ALPHA)."""
    cells: dict = {}
    for s in _seed_runs(summaries, env):
        for c in s.get("comparisons", []):
            kind = c["query_kind"]
            key = (not bool(c.get("steer", True)), _model_key(c["model"]),
                   KINDS.index(kind) if kind in KINDS else 9, c["model"], c["baseline"], kind,
                   bool(c.get("steer", True)))
            cells.setdefault(key, []).append((s.get("train_seed"), c))
    out = []
    for key in sorted(cells):
        got = cells[key]
        d = [c["success_diff"] for _, c in got]
        out.append({"model": key[3], "baseline": key[4], "query_kind": key[5], "steer": key[6],
                    "seeds": sorted((k for k, _ in got), key=str),
                    "diff_mean": sum(d) / len(d), "diff_min": min(d), "diff_max": max(d),
                    "significant": sum(_num(c.get("mcnemar_p")) and c["mcnemar_p"] < ALPHA
                                       for _, c in got)})
    return out


# ---------------------------------------------------------------------------
# The document
# ---------------------------------------------------------------------------


def _root_label(root) -> str:
    """``root`` as the repository spells it (from its ``results`` folder on), whatever the
    working directory."""
    parts = Path(root).resolve().parts
    return "/".join(parts[parts.index("results"):]) if "results" in parts else Path(root).name


def _header(summaries, label: str = "results/paper") -> list[str]:
    cmds = sorted({s.get("command") for s in summaries if s.get("command")})
    out = ["# Reproduction of the paper's Tables I-IV", "",
           'Paper: Sagar Suhas Joshi and Panagiotis Tsiotras, "Non-Trivial Query Sampling For '
           'Efficient Learning To Plan". Its numbers and sizes are transcribed in '
           "`ntq_jax/reproduction.py` (`PAPER`, `PAPER_K_TRAIN`, `PAPER_K_TEST`, `PAPER_PADDING`).",
           "",
           "Generated from the committed summaries (`<task>/<map>/summary.json`, seed runs in "
           "`<task>/<map>/seeds/train_seed_<k>/summary.json`) by "
           f"`python -m ntq_jax.reproduction {label}` (do not edit by hand; "
           f"`python -m ntq_jax.reproduction {label} --check` tells whether it is current; "
           "`python scripts/reproduce.py --report-only` regenerates it too). "
           "The summaries were made with:", ""]
    out += [f"    {c}" for c in cmds] or ["    (no summary yet: `python scripts/reproduce.py ...`)"]
    out += ["", "Success ratio: successes / K_test, with its 95% Wilson interval. Cost ratio: "
            "neural cost / reference planner cost, mean over the queries both solve. Paired "
            "differences are on the same test queries: model minus baseline, Newcombe's 95% "
            "interval and McNemar's exact p.", ""]
    return out


def _coverage(summaries) -> list[str]:
    main = _main_runs(summaries)
    out = ["## Coverage", "",
           "| Table | Map | status | K_train | K_test | padding | train seed | package | "
           "config hash | finished | check |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    missing = []
    for tid, spec in PAPER_TABLES.items():
        for env in spec["envs"]:
            s = main.get(env)
            present = s is not None and bool(_cell(s, spec["steer"]))
            if not present:
                missing.append(f"{tid} {env}")
                out.append(f"| {tid} | {env} | missing | - | - | - | - | - | - | - | - |")
                continue
            probs = check_summary(s)
            cfg = s.get("config") or {}
            out.append(f"| {tid} | {env} | present | {_k_train(cfg, env)} | "
                       f"{cfg.get('eval', {}).get('k_test')} | {s.get('padding')} | "
                       f"{s.get('train_seed')} | {s.get('package_version', '-')} | "
                       f"{s.get('config_hash', '-')} | {s.get('finished', '-')} | "
                       f"{'ok' if not probs else '; '.join(probs)} |")
    n_maps = sum(1 for e in MAPS if e in main and _cell(main[e], True))
    n3 = sum(1 for e in PAPER_TABLES["III"]["envs"] if e in main and _cell(main[e], False))
    out += ["", f"Maps with steerTo: {n_maps} of {len(MAPS)}; Table III (rigid without "
            f"steerTo): {n3} of {len(PAPER_TABLES['III']['envs'])}."]
    out.append("Missing: " + (", ".join(missing) if missing else "none") + ".")
    extra = sorted({s.get("env") for s in summaries if s.get("env") not in MAPS}, key=str)
    if extra:
        out.append("Not maps of the paper (ignored): " + ", ".join(map(str, extra)) + ".")
    seeds = []
    for env in SEED_MAPS:
        ks = sorted({s.get("train_seed") for s in summaries if s.get("env") == env}, key=str)
        seeds.append(f"{env} {len(ks)} of 3" + (f" ({', '.join(map(str, ks))})" if ks else ""))
    bad = [f"`{s['_path']}`: {'; '.join(p)}." for s in summaries
           if is_seed_run(s) and (p := check_summary(s))] + [
        f"{p}." for p in check_seed_runs(summaries)]
    out += [f"Seed-variance runs (training seeds found): {'; '.join(seeds)}."]
    if bad:
        out += ["Seed-run problems: " + " ".join(bad)]
    return out + [""]


def _table_block(tid: str, env: str, s) -> list[str]:
    spec = PAPER_TABLES[tid]
    paper = PAPER[tid][env]
    cell = _cell(s, spec["steer"])
    r0 = cell.get(("PNet_0", "uniform")) or next(iter(cell.values()), None)
    g = None if r0 is None else r0.get("gamma_nt")
    out = [f"### {env}: gamma_nt {_f(g)}{_ci(None if r0 is None else r0.get('gamma_nt_ci95'))} "
           f"(paper {paper['gamma_nt']:.3f})", ""]
    if not cell:
        return out + ["Not run yet.", ""]
    out += ["| Model | uniform success [95%] | paper | uniform cost ratio | paper | "
            "non-trivial success [95%] | paper | non-trivial cost ratio | paper |",
            "|---|---|---|---|---|---|---|---|---|"]
    models = sorted({m for m, _ in cell} | set(MEMBERS), key=_model_key)
    for m in models:
        cells = []
        for kind in KINDS:
            r = cell.get((m, kind))
            pm = paper["models"].get(m, {}).get(kind)
            cells += [("-" if r is None else _f(r["success_ratio"]) + _ci(r.get("success_ci95"))),
                      "-" if pm is None else _f(pm["success"]),
                      "-" if r is None else _f(r.get("cost_ratio")),
                      "-" if pm is None else _f(pm["cost"])]
        out.append(f"| {m} | " + " | ".join(cells) + " |")
    refs = sorted({(r.get("reference_planner"), r.get("data_planner")) for r in cell.values()},
                  key=str)
    out += ["", "Reference planner (cost ratio denominator): " +
            ", ".join(f"{a} (data: {b})" for a, b in refs) + "."]
    comps = sorted((c for c in s.get("comparisons", [])
                    if bool(c.get("steer", True)) == spec["steer"]),
                   key=lambda c: (_model_key(c["model"]), KINDS.index(c["query_kind"])
                                  if c["query_kind"] in KINDS else 9))
    if comps:
        out += ["", "| Model | vs | kind | success diff [95%] | McNemar p | paper diff | "
                "cost ratio diff [95%] | Wilcoxon p |", "|---|---|---|---|---|---|---|---|"]
        for c in comps:
            pm, pb = paper["models"].get(c["model"]), paper["models"].get(c["baseline"])
            pdiff = ("-" if pm is None or pb is None or c.get("baseline_rule")
                     else _signed(pm[c["query_kind"]]["success"] - pb[c["query_kind"]]["success"]))
            vs = c["baseline"] + (f" ({c['baseline_rule']})" if c.get("baseline_rule") else "")
            out.append(f"| {c['model']} | {vs} | {_kind_name(c['query_kind'])} | "
                       f"{_signed(c['success_diff'])}{_ci(c.get('success_diff_ci95'))} | "
                       f"{_p(c.get('mcnemar_p'))} | {pdiff} | "
                       f"{_signed(c.get('cost_ratio_diff'))}{_ci(c.get('cost_ratio_diff_ci95'))} | "
                       f"{_p(c.get('wilcoxon_p'))} |")
    return out + [""]


def _tables(summaries) -> list[str]:
    main = _main_runs(summaries)
    out = []
    for tid, spec in PAPER_TABLES.items():
        out += [f"## Table {tid}: {spec['title']}", ""]
        for env in spec["envs"]:
            out += _table_block(tid, env, main.get(env))
    return out


def _ms(x) -> str:
    return f"{1e3 * x:.2f}" if _num(x) else "-"


def _datasets(summaries) -> list[str]:
    """Per map, each dataset's planned paths, samples and mean states per data path (the
    summaries that record them)."""
    main = _main_runs(summaries)
    rows = [(env, main[env]["datasets"]) for env in MAPS
            if env in main and isinstance(main[env].get("datasets"), dict)]
    if not rows:
        return []
    names = sorted({n for _, d in rows for n in d}, key=lambda n: (len(n), n))
    out = ["## Datasets", "",
           "Per dataset: planned paths used / samples written (includeData, Alg. 4) / mean "
           "states per data path; D3's samples are D2's paths after pruning.", "",
           "| Map | data paths | " + " | ".join(names) + " |",
           "|---|---|" + "---|" * len(names)]
    for env, d in rows:
        cfg = (main[env].get("config") or {}).get("planner") or {}
        mode = next((o.get("data_paths") for o in cfg.get("per_env") or ()
                     if o.get("env") == env and o.get("data_paths") is not None),
                    cfg.get("data_paths"))
        cells = [f"{v['paths']} / {v['samples']} / {v['states_per_path']:.1f}" if v else "-"
                 for v in (d.get(n) for n in names)]
        out.append(f"| {env} | {'default' if mode is None else mode} | " + " | ".join(cells) + " |")
    return out + [""]


def _times(summaries) -> list[str]:
    main = _main_runs(summaries)
    out = ["## Time per query (ms)", "",
           "Neural planner per model, and the reference planner, per test query (mean).", "",
           "| Map | steerTo | kind | " + " | ".join(MEMBERS) + " | ensemble rows | reference |",
           "|---|---|---|" + "---|" * len(MEMBERS) + "---|---|"]
    for env in MAPS:
        s = main.get(env)
        for steer in (True, False):
            cell = _cell(s, steer)
            for kind in KINDS:
                rows = {m: r for (m, k), r in cell.items() if k == kind}
                if not rows:
                    continue
                ens = ", ".join(f"{m} {_ms(rows[m].get('seconds_per_query'))}"
                                for m in sorted(rows, key=_model_key) if m not in MEMBERS) or "-"
                ref = next((r.get("reference_seconds_per_query") for r in rows.values()), None)
                out.append(f"| {env} | {'yes' if steer else 'no'} | {_kind_name(kind)} | " +
                           " | ".join(_ms(rows[m].get("seconds_per_query")) if m in rows else "-"
                                      for m in MEMBERS) + f" | {ens} | {_ms(ref)} |")
    out += ["", "## Time per stage (s)", "", "| Run | data | train | eval | total |",
            "|---|---|---|---|---|"]
    tot = {"data": 0.0, "train": 0.0, "eval": 0.0}
    for s in summaries:
        tm = s.get("timings") or {}
        vals = [tm.get(k) for k in tot]
        for k, v in zip(tot, vals):
            tot[k] += v if _num(v) else 0.0
        run = s.get("env", "?") + (f" (train seed {s.get('train_seed')})" if is_seed_run(s) else "")
        out.append(f"| {run} | " + " | ".join(_f(v, 1) for v in vals) +
                   f" | {_f(sum(v for v in vals if _num(v)), 1)} |")
    out.append("| total | " + " | ".join(_f(v, 1) for v in tot.values()) +
               f" | {_f(sum(tot.values()), 1)} |")
    return out + [""]


def _seeds(summaries) -> list[str]:
    out = ["## Seed variance", "",
           "Same data, different training seeds (the main run and `seeds/train_seed_<k>`): mean "
           "and range [min, max] over the seeds found.", ""]
    envs = [e for e in list(SEED_MAPS) + sorted({s.get("env") for s in summaries if is_seed_run(s)}
                                                 - set(SEED_MAPS), key=str)]
    for env in envs:
        stats = seed_variance(summaries, env)
        out += [f"### {env}", ""]
        if not stats:
            out += ["Not run yet.", ""]
            continue
        seeds = sorted({str(k) for st in stats for k in st["seeds"]})
        out += [f"Training seeds found: {', '.join(seeds)}" +
                ("" if len(seeds) >= 3 else f" ({3 - len(seeds)} missing of 3)") + ".", "",
                "| Model | steerTo | kind | seeds | success mean | range | cost ratio mean | range |",
                "|---|---|---|---|---|---|---|---|"]
        for st in stats:
            out.append(f"| {st['model']} | {'yes' if st['steer'] else 'no'} | "
                       f"{_kind_name(st['query_kind'])} | {len(st['seeds'])} | "
                       f"{_f(st['success_mean'])} | [{_f(st['success_min'])}, "
                       f"{_f(st['success_max'])}] | {_f(st['cost_mean'])} | "
                       f"[{_f(st['cost_min'])}, {_f(st['cost_max'])}] |")
        diffs = seed_variance_diffs(summaries, env)
        if diffs:
            out += ["", "Paired success differences over the seeds (an ensemble row's baseline is "
                    "each seed's best member; another best member is another line):", "",
                    "| Model | vs | steerTo | kind | seeds | diff mean | range | "
                    "seeds with McNemar p < 0.05 |", "|---|---|---|---|---|---|---|---|"]
            for d in diffs:
                out.append(f"| {d['model']} | {d['baseline']} | {'yes' if d['steer'] else 'no'} | "
                           f"{_kind_name(d['query_kind'])} | {len(d['seeds'])} | "
                           f"{_signed(d['diff_mean'])} | [{_signed(d['diff_min'])}, "
                           f"{_signed(d['diff_max'])}] | {d['significant']} |")
        out.append("")
    return out


def _claims_md(summaries) -> list[str]:
    cs = claims(summaries)
    counts = {v: sum(c["verdict"].startswith(v) for c in cs)
              for v in (HOLDS, FAILS, UNRESOLVED, NOT_RUN)}
    out = ["## Claims of the paper", "",
           f"Rule (level {ALPHA}): a claim that A's success is at least B's holds if our "
           "difference has the claimed sign with p < 0.05, does not hold if it has the opposite "
           "sign with p < 0.05, and is not resolvable at this K_test otherwise. p: McNemar's "
           "exact test on the same queries (pooled over a task's maps by summing the discordant "
           "pairs), or Fisher's exact test when the samples differ or no paired comparison was "
           "saved. A claim of several parts holds if all parts hold and does not hold if one "
           "does not. Trends in gamma_nt: Kendall's tau with its exact one-sided p (4 or more "
           "maps needed). Details in the docstring of `ntq_jax/reproduction.py`.", "",
           "Verdicts: " + ", ".join(f"{v} {n}" for v, n in counts.items()) + ".", "",
           "| Table | Claim | Scope | Verdict | Ours | Paper |", "|---|---|---|---|---|---|"]
    for c in cs:
        out.append(f"| {c['table']} | {c['claim']} | {c['scope']} | **{c['verdict']}** | "
                   f"{c['evidence']} | {c['paper']} |")
    return out + [""]


def render(root) -> str:
    """The whole ``REPRODUCTION.md`` of the summaries under ``root`` (deterministic)."""
    summaries = load_summaries(root)
    lines = (_header(summaries, _root_label(root)) + _coverage(summaries) + _tables(summaries)
             + _datasets(summaries) + _times(summaries)
             + _seeds(summaries) + _claims_md(summaries))
    return "\n".join(lines).rstrip("\n") + "\n"


def write(root) -> Path:
    """Writes ``<root>/REPRODUCTION.md`` (atomically) and returns its path."""
    return artifacts.write_text(Path(root) / DOC_NAME, render(root))


def main(argv=None) -> int:
    """``python -m ntq_jax.reproduction [root] [--check]``."""
    ap = argparse.ArgumentParser(prog="python -m ntq_jax.reproduction",
                                 description="Write <root>/REPRODUCTION.md from the summaries.")
    ap.add_argument("root", nargs="?", default="results/paper")
    ap.add_argument("--check", action="store_true",
                    help="write nothing; exit 1 if the file on disk is not what render gives")
    a = ap.parse_args(argv)
    path = Path(a.root) / DOC_NAME
    try:
        return _main(a, path)
    except SummaryError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2


def _main(a, path: Path) -> int:
    if a.check:
        current = path.read_text(encoding="utf-8") if path.exists() else None
        if current != render(a.root):
            what = "is missing" if current is None else "is out of date"
            print(f"{path} {what}; regenerate with python -m ntq_jax.reproduction {a.root}")
            return 1
        print(f"{path} is up to date")
        return 0
    print(write(a.root))
    return 0


if __name__ == "__main__":
    sys.exit(main())
