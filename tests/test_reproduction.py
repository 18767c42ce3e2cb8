"""REPRODUCTION.md from committed summaries (ntq_jax.experiment.reproduction).

Synthetic summaries (built here, in the shape of a run's results.json rows and
comparisons) check the document: deterministic, the paper's numbers next to ours,
missing maps listed, the claim verdicts on hand-made cases (holds / does not hold /
not resolvable / too few maps), the seed variance, check_summary and the command
line. The last two tests are over the real committed tree ``results/paper``: the
committed REPRODUCTION.md is what render gives, and every committed summary is a
paper-size run (both skip while no summary is committed).
"""

import copy
import json
from pathlib import Path

import pytest

from ntq_jax.experiment import claims as CL
from ntq_jax.experiment import paper as PA
from ntq_jax.experiment import reproduction as R
from ntq_jax.experiment import summaries as S
from ntq_jax.stats import mcnemar_exact

REPO = Path(__file__).resolve().parent.parent
PAPER_ROOT = REPO / "results" / "paper"

K = PA.PAPER_K_TEST
GAMMA = {
    "point/0": 0.31,
    "point/1": 0.40,
    "point/2": 0.41,
    "point/3": 0.63,
    "rigid/0": 0.50,
    "rigid/1": 0.66,
    "rigid/2": 0.56,
    "rigid/3": 0.69,
    "nlink/2": 0.22,
    "nlink/4": 0.37,
    "nlink/6": 0.61,
}


def _row(env, model, kind, steer, successes, cost=1.01, gamma=None):
    p = successes / K
    return {
        "task": env.split("/")[0],
        "env": env,
        "env_slug": env.replace("/", "_"),
        "model": model,
        "query_kind": kind,
        "steer": steer,
        "gamma_nt": GAMMA[env] if gamma is None else gamma,
        "gamma_nt_ci95": [GAMMA[env] - 0.002, GAMMA[env] + 0.002],
        "reference_planner": "roadmap",
        "data_planner": "roadmap",
        "seconds_per_query": 0.002,
        "reference_seconds_per_query": 0.01,
        "k_test": K,
        "successes": successes,
        "success_ratio": p,
        "success_ci95": [max(0.0, p - 0.04), min(1.0, p + 0.04)],
        "cost_ratio": cost,
        "cost_ratio_n": successes,
    }


def _comp(env, model, baseline, kind, steer, only_a, only_b, both=300, ci=None):
    d = (only_a - only_b) / K
    return {
        "task": env.split("/")[0],
        "env": env,
        "steer": steer,
        "query_kind": kind,
        "model": model,
        "baseline": baseline,
        "baseline_rule": None,
        "n": K,
        "both": both,
        "only_a": only_a,
        "only_b": only_b,
        "neither": K - both - only_a - only_b,
        "success_diff": d,
        "success_diff_ci95": ci or [d - 0.04, d + 0.04],
        "mcnemar_p": mcnemar_exact(only_a, only_b),
        "cost_n": both,
        "cost_ratio_diff": 0.001,
        "cost_ratio_diff_ci95": [-0.01, 0.012],
        "wilcoxon_p": 0.5,
    }


def _config(env):
    task = env.split("/")[0]
    return {
        "task": task,
        "envs": [env],
        "seed": 0,
        "data": {
            "k_train": PA.PAPER_K_TRAIN[env],
            "per_env": [],
            "datasets": [dict(d) for d in PA.PAPER_DATASETS],
        },
        "model": {"hidden": [64, 32]},
        "eval": {"k_test": K, "steer": [True, False] if task == "rigid" else [True]},
    }


def make_summary(env, successes=None, comparisons=(), train_seed=0, gamma=None):
    """A paper-size summary of ``env``: every member on both kinds (400 successes unless
    ``successes[(model, kind, steer)]`` says otherwise), rigid also without steerTo."""
    successes = successes or {}
    task = env.split("/")[0]
    steers = (True, False) if task == "rigid" else (True,)
    rows = [
        _row(env, m, k, s, successes.get((m, k, s), 400), gamma=gamma)
        for s in steers
        for m in PA.MEMBERS
        for k in PA.KINDS
    ]
    rows += [
        _row(env, m, k, s, n, gamma=gamma)
        for (m, k, s), n in successes.items()
        if m not in PA.MEMBERS
    ]
    return {
        "schema": 1,
        "task": task,
        "env": env,
        "env_slug": env.replace("/", "_"),
        "seed": 0,
        "train_seed": train_seed,
        "package_version": "0.1.0",
        "config_hash": "0123456789abcdef",
        "config": _config(env),
        "padding": PA.PAPER_PADDING[task],
        "rows": rows,
        "comparisons": list(comparisons),
        "fingerprints": {"datasets": {f"D{i}": f"{i}" * 64 for i in range(4)}, "models": "f" * 64},
        "timings": {"data": 10.0, "train": 20.0, "eval": 5.5},
        "finished": "2026-12-01T20:00:00",
        "command": f"python scripts/reproduce.py --env {env}",
    }


def write_summary(root, summary, seed_dir=None):
    task, slug = summary["task"], summary["env_slug"]
    d = Path(root) / task / slug
    if seed_dir is not None:
        d = d / "seeds" / f"train_seed_{seed_dir}"
    d.mkdir(parents=True, exist_ok=True)
    (d / "summary.json").write_text(json.dumps(summary))
    return d


def _find(claims, claim_start, scope_start):
    got = [
        c
        for c in claims
        if c["claim"].startswith(claim_start) and c["scope"].startswith(scope_start)
    ]
    assert got, (claim_start, scope_start)
    return got[0]


# ---------------------------------------------------------------------------
# The paper's numbers
# ---------------------------------------------------------------------------


def test_paper_tables_transcribed():
    assert sum(len(envs) for envs in PA.PAPER.values()) == 15
    assert all(set(e["models"]) == set(PA.MEMBERS) for t in PA.PAPER.values() for e in t.values())
    assert PA.PAPER["I"]["point/0"]["models"]["PNet_0"]["uniform"] == {
        "success": 0.970,
        "cost": 1.004,
    }
    assert PA.PAPER["II"]["rigid/1"]["gamma_nt"] == 0.659
    assert PA.PAPER["III"]["rigid/0"]["models"]["PNet_3"]["uniform"]["success"] == 0.228
    assert PA.PAPER["IV"]["nlink/4"]["models"]["PNet_3"]["nontrivial"]["success"] == 0.82
    assert PA.PAPER["IV"]["nlink/6"]["models"]["PNet_3"]["nontrivial"]["cost"] == 0.958
    for tid, spec in PA.PAPER_TABLES.items():
        assert tuple(PA.PAPER[tid]) == spec["envs"]
    assert PA.PAPER_K_TRAIN["nlink/4"] == 4000 and PA.PAPER_K_TRAIN["rigid/2"] == 5000
    assert PA.PAPER_PADDING == {"point": 0.8, "rigid": 0.4, "nlink": 0.8}
    assert tuple(PA.PAPER_K_TRAIN) == PA.MAPS


# ---------------------------------------------------------------------------
# The document
# ---------------------------------------------------------------------------


def test_render_is_deterministic_and_puts_the_paper_next_to_ours(tmp_path):
    s = make_summary(
        "point/0",
        {("PNet_0", "uniform", True): 452, ("PNet_ens", "nontrivial", True): 470},
        [_comp("point/0", "PNet_3", "PNet_0", "nontrivial", True, 40, 10)],
    )
    write_summary(tmp_path, s)
    text = R.render(tmp_path)
    assert text == R.render(tmp_path)
    assert text.endswith("\n") and not text.endswith("\n\n")
    # ours [95%] | paper, for PNet_0 uniform (0.904 vs the paper's 0.970 / 1.004)
    line = next(x for x in text.splitlines() if x.startswith("| PNet_0 | 0.904 ["))
    assert "| 0.970 | 1.010 | 1.004 |" in line and "| 0.894 |" in line
    assert "| PNet_ens | - | - | - | - | 0.940 [" in text  # ensemble rows: ours only
    assert "gamma_nt 0.310 [0.308, 0.312] (paper 0.311)" in text
    assert "| PNet_3 | PNet_0 | non-trivial | +0.060 [0.020, 0.100] |" in text
    assert "python scripts/reproduce.py --env point/0" in text
    # the command names the folder as the repository spells it, from results/ on
    assert f"python scripts/reproduce.py --report-only --results {tmp_path.name}" in text
    assert R._root_label(REPO / "results" / "ablations" / "x") == "results/ablations/x"
    assert "roadmap (data: roadmap)" in text
    assert "| point/0 | 10.0 | 20.0 | 5.5 | 35.5 |" in text


def test_missing_maps_are_listed(tmp_path):
    write_summary(tmp_path, make_summary("point/0"))
    write_summary(tmp_path, make_summary("rigid/1"))
    text = R.render(tmp_path)
    assert "Maps with steerTo: 2 of 11; Table III (rigid without steerTo): 1 of 4." in text
    missing = next(x for x in text.splitlines() if x.startswith("Missing: "))
    for m in ("I point/1", "II rigid/0", "III rigid/3", "IV nlink/6"):
        assert m in missing
    assert "I point/0" not in missing and "rigid/1" not in missing
    assert "| IV | nlink/2 | missing |" in text and "| II | rigid/1 | present |" in text


def test_empty_root_renders(tmp_path):
    text = R.render(tmp_path / "nothing")
    assert "Maps with steerTo: 0 of 11" in text and "not run" in text
    assert S.load_summaries(tmp_path / "nothing") == []


def test_load_summaries_order(tmp_path):
    for env in ("nlink/4", "point/1", "rigid/0", "point/0"):
        write_summary(tmp_path, make_summary(env))
    write_summary(tmp_path, make_summary("point/0", train_seed=2), seed_dir=2)
    write_summary(tmp_path, make_summary("point/0", train_seed=1), seed_dir=1)
    got = [(s["env"], s["train_seed"], S.is_seed_run(s)) for s in S.load_summaries(tmp_path)]
    assert got == [
        ("point/0", 0, False),
        ("point/0", 1, True),
        ("point/0", 2, True),
        ("point/1", 0, False),
        ("rigid/0", 0, False),
        ("nlink/4", 0, False),
    ]


# ---------------------------------------------------------------------------
# Claims (the seed-aware test, Holm, the verdict rule)
# ---------------------------------------------------------------------------


def write_seeds(
    root,
    env,
    per_seed,
    kind="nontrivial",
    steer=True,
    model="PNet_3",
    baseline="PNet_0",
    successes=None,
):
    """One summary per training seed of ``env``, each with the paired comparison
    ``model - baseline`` given by its discordant pairs ``(only_a, only_b)``."""
    for seed, (a, b) in enumerate(per_seed):
        s = make_summary(
            env, successes, [_comp(env, model, baseline, kind, steer, a, b)], train_seed=seed
        )
        write_summary(root, s, seed_dir=None if seed == 0 else seed)


def test_verdict_rule():
    assert CL.verdict(1, 0.01) == CL.HOLDS
    assert CL.verdict(-1, 0.01) == CL.CONTRADICTED == CL.FAILS
    assert CL.verdict(1, 0.2) == CL.UNRESOLVED
    assert CL.verdict(1, 0.2, 0.01) == CL.MAGNITUDE  # the paper's size excluded
    assert CL.verdict(1, 0.01, 0.01) == CL.HOLDS  # the sign first
    assert CL.verdict(-1, 0.01, 0.01) == CL.CONTRADICTED
    assert CL.verdict(1, 0.01, 0.01, magnitude_claim=True) == CL.CONTRADICTED
    assert CL.verdict(0, None) == CL.NOT_RUN


def test_claim_verdicts_with_training_seeds(tmp_path):
    write_seeds(tmp_path, "point/0", [(120, 20), (110, 20), (125, 25)])  # +0.2 in every seed
    write_seeds(tmp_path, "point/1", [(20, 120), (20, 110), (25, 125)])  # -0.2
    write_seeds(tmp_path, "point/2", [(30, 28), (25, 30), (35, 28)])  # about 0
    cs = CL.claims(S.load_summaries(tmp_path))
    text = "PNet_3 >= PNet_0 in success on non-trivial"
    c0 = _find(cs, text, "point/0")
    assert c0["verdict"] == CL.HOLDS and c0["seeds"] == 3
    assert c0["estimate"].estimate == pytest.approx((100 + 90 + 100) / 3 / K)
    assert c0["effect"].startswith("+0.193 [") and ", 3 seeds, sd 0.012" in c0["effect"]
    assert "per seed +0.200, +0.180, +0.200" in c0["evidence"]
    assert c0["paper"] == "0.930 vs 0.894 (+0.036)"
    assert _find(cs, text, "point/1")["verdict"] == CL.CONTRADICTED
    assert _find(cs, text, "point/2")["verdict"] == CL.UNRESOLVED
    assert _find(cs, text, "point/3")["verdict"] == CL.NOT_RUN
    # pooled over the robot: not run until all four maps are there
    assert _find(cs, text, "point, pooled")["verdict"] == CL.NOT_RUN
    # Holm over every p-value the verdicts use (the lines' and the paper's size tests)
    fam = [c["p"] for c in cs if c["p"] is not None] + [
        c["p_paper"] for c in cs if c["p_paper"] is not None
    ]
    assert CL.family_size(cs) == len(fam)
    assert all(c["p_holm"] >= c["p"] for c in cs if c["p"] is not None)
    from ntq_jax.stats import holm

    assert c0["p_holm"] == pytest.approx(holm(fam)[fam.index(c0["p"])])


def test_a_null_effect_that_excludes_the_papers_size(tmp_path):
    # rigid/0: the paper's PNet_3 - PNet_0 is +0.128; ours is about 0 in three seeds
    write_seeds(tmp_path, "rigid/0", [(30, 30), (32, 30), (28, 30)])
    c = _find(
        CL.claims(S.load_summaries(tmp_path)),
        "PNet_3 >= PNet_0 in success on non-trivial",
        "rigid/0",
    )
    assert c["verdict"] == CL.MAGNITUDE and c["p_paper_holm"] < 0.05 and c["p_holm"] > 0.05
    assert c["paper_effect"] == pytest.approx(0.128)


def test_one_seed_maps_borrow_their_robots_spread(tmp_path):
    write_seeds(tmp_path, "nlink/4", [(80, 30), (70, 40), (90, 30)])
    write_seeds(tmp_path, "nlink/2", [(80, 30)])
    write_seeds(tmp_path, "point/0", [(80, 30)])  # no point map with seeds: nothing to borrow
    cs = CL.claims(S.load_summaries(tmp_path))
    text = "PNet_3 >= PNet_0 in success on non-trivial"
    c2, c4 = _find(cs, text, "nlink/2"), _find(cs, text, "nlink/4")
    e2, e4 = c2["estimate"], c4["estimate"]
    assert e2.borrowed and e2.seeds == 1 and "1 seed, sd borrowed" in c2["effect"]
    # the borrowed variance is nlink/4's between-seed variance, with its 2 df
    assert e2.seed_part == pytest.approx((e4.spread**2, 2))
    p0 = _find(cs, text, "point/0")
    assert p0["verdict"] == CL.UNRESOLVED and p0["p"] is None
    assert "between-seed variance is unknown" in p0["evidence"]


def test_pooled_claim_is_the_mean_of_the_maps(tmp_path):
    for env, seeds in zip(
        PA.PAPER_TABLES["IV"]["envs"],
        [[(20, 10), (30, 10)], [(15, 10)], [(15, 10), (25, 10), (20, 10)]],
    ):
        write_seeds(tmp_path, env, seeds)
    cs = CL.claims(S.load_summaries(tmp_path))
    c = _find(cs, "PNet_3 >= PNet_0 in success on non-trivial", "nlink, pooled")
    maps = [
        _find(cs, "PNet_3 >= PNet_0 in success on non-trivial", e)["estimate"]
        for e in PA.PAPER_TABLES["IV"]["envs"]
    ]
    assert c["estimate"].estimate == pytest.approx(sum(m.estimate for m in maps) / 3)
    assert c["estimate"].variance == pytest.approx(sum(m.variance for m in maps) / 9)
    assert c["seeds"] == 6 and "mean diff +0.093; PNet_3 ahead in 3 of 3" in c["paper"]


def test_without_steer_pnet3_worst(tmp_path):
    low = {("PNet_3", k, False): 150 for k in PA.KINDS}
    low.update({(m, k, False): 300 for m in ("PNet_0", "PNet_1", "PNet_2") for k in PA.KINDS})
    write_seeds(
        tmp_path,
        "rigid/0",
        [(10, 160), (12, 158), (9, 161)],
        kind="uniform",
        steer=False,
        successes=low,
    )
    high = dict(low)
    high[("PNet_3", "uniform", False)] = 400  # above PNet_1 and PNet_2 (unpaired rows)
    write_seeds(tmp_path, "rigid/1", [(0, 0)] * 2, kind="nontrivial", steer=False, successes=high)
    cs = CL.claims(S.load_summaries(tmp_path))
    c = _find(cs, "without steerTo PNet_3 is the worst", "rigid/0, uniform")
    assert c["verdict"] == CL.HOLDS  # below each of PNet_0 (paired), PNet_1, PNet_2 (rows)
    assert "vs PNet_0 -0.299" in c["evidence"] and "vs PNet_1 -0.300" in c["evidence"]
    assert (
        _find(cs, "without steerTo PNet_3 is the worst", "rigid/1, uniform")["verdict"]
        == CL.CONTRADICTED
    )
    assert (
        _find(cs, "without steerTo PNet_3 is the worst", "rigid/2, uniform")["verdict"]
        == CL.NOT_RUN
    )
    assert _find(cs, "the success of every model falls", "rigid, PNet_0")["verdict"] == CL.NOT_RUN


def test_success_falls_with_gamma_within_robots(tmp_path):
    # every robot: the higher gamma_nt, the lower the success (both kinds)
    for table in ("I", "II", "IV"):
        for i, env in enumerate(PA.PAPER_TABLES[table]["envs"]):
            n = 480 - 30 * sorted(PA.PAPER_TABLES[table]["envs"], key=GAMMA.get).index(env)
            write_summary(
                tmp_path,
                make_summary(
                    env, {(m, k, s): n for m in PA.MEMBERS for k in PA.KINDS for s in (True, False)}
                ),
            )
    cs = CL.claims(S.load_summaries(tmp_path))
    c = _find(cs, "success falls as gamma_nt rises (uniform", "point")
    assert c["effect"].startswith("Kendall tau -1.00 over 4 maps (4 maps: the smallest")
    assert c["p"] == pytest.approx(2 / 24) and c["verdict"] == CL.UNRESOLVED
    c = _find(cs, "success falls as gamma_nt rises (non-trivial", "all 11 maps")
    assert c["table"] == "I, II, IV" and "tau -1.00 within robots over 11 maps" in c["effect"]
    assert c["p"] == pytest.approx(2 / (24 * 24 * 6)) and c["direction"] == 1


def test_six_link_25_percent(tmp_path):
    big = {("PNet_0", "nontrivial", True): 200, ("PNet_3", "nontrivial", True): 250}
    write_seeds(tmp_path, "nlink/6", [(70, 20), (72, 22), (68, 18)], successes=big)
    c = _find(CL.claims(S.load_summaries(tmp_path)), "PNet_3 about 25%", "nlink/6")
    assert c["verdict"] == CL.HOLDS and "+25.0% of our PNet_0 0.400" in c["evidence"]
    assert c["paper"] == "0.644 vs 0.512 (+25.8%)" and c["magnitude_claim"]
    small = {("PNet_0", "nontrivial", True): 200, ("PNet_3", "nontrivial", True): 210}
    write_seeds(tmp_path, "nlink/6", [(30, 20), (31, 21), (29, 19)], successes=small)
    c = _find(CL.claims(S.load_summaries(tmp_path)), "PNet_3 about 25%", "nlink/6")
    assert c["verdict"] == CL.CONTRADICTED  # the claimed +0.100 is excluded
    assert c["evidence"].endswith("(our gain is smaller)")


def test_point_over_90_percent(tmp_path):
    def seeds(env, succ):
        for seed in range(3):
            write_summary(
                tmp_path,
                make_summary(env, succ, train_seed=seed),
                seed_dir=None if seed == 0 else seed,
            )

    seeds("point/0", {(m, k, True): 490 for m in PA.MEMBERS for k in PA.KINDS})
    seeds(
        "point/1",
        {(m, k, True): 490 for m in PA.MEMBERS for k in PA.KINDS}
        | {("PNet_2", "nontrivial", True): 400},
    )
    seeds("point/2", {(m, k, True): 455 for m in PA.MEMBERS for k in PA.KINDS})
    cs = CL.claims(S.load_summaries(tmp_path))
    text = "every model succeeds on over 90%"
    assert _find(cs, text, "point/0")["verdict"] == CL.HOLDS  # 0.98 in every seed
    c = _find(cs, text, "point/1")
    assert c["verdict"] == CL.CONTRADICTED and c["effect"].startswith("PNet_2 non-trivial: 0.800")
    assert _find(cs, text, "point/2")["verdict"] == CL.UNRESOLVED  # 0.91


def test_nlink_gain_grows_with_links(tmp_path):
    for env, ab in zip(PA.PAPER_TABLES["IV"]["envs"], [(12, 10), (60, 10), (80, 10)]):
        write_seeds(tmp_path, env, [ab, (ab[0] + 2, ab[1]), (ab[0] - 2, ab[1])])
    c = _find(CL.claims(S.load_summaries(tmp_path)), "PNet_3's gain over PNet_0", "nlink")
    assert c["verdict"] == CL.HOLDS  # gains +0.004, +0.100, +0.140
    assert "nlink/4 minus nlink/2 +0.096" in c["evidence"]
    assert c["effect"].startswith("nlink/4 minus nlink/2: +0.096")  # the weaker part decides
    write_seeds(tmp_path, "nlink/6", [(15, 10), (17, 10), (13, 10)])
    c = _find(CL.claims(S.load_summaries(tmp_path)), "PNet_3's gain over PNet_0", "nlink")
    assert c["verdict"] == CL.UNRESOLVED  # 4 links: larger; 6 links: not resolvable


def test_cost_ratio_lower_for_rigid_and_six_links(tmp_path):
    for env in PA.MAPS:
        s = make_summary(env)
        low = env.startswith("rigid") or env == "nlink/6"
        for r in s["rows"]:
            r["cost_ratio"] = (0.95 if low else 1.03) + PA.MAPS.index(env) * 1e-3
        write_summary(tmp_path, s)
    c = _find(CL.claims(S.load_summaries(tmp_path)), "cost ratio lower", "rigid")
    assert c["p"] == pytest.approx(2 / 462) and c["direction"] == 1  # 5 of 11 maps lowest
    assert "not the paper's BIT*" in c["scope"] and "rigid roadmap" in c["scope"]
    (tmp_path / "point" / "point_3" / "summary.json").unlink()
    c = _find(CL.claims(S.load_summaries(tmp_path)), "cost ratio lower", "rigid")
    assert c["verdict"] == CL.NOT_RUN and c["evidence"] == "10 of 11 maps run"


def test_summary_page_heads_the_document(tmp_path):
    write_seeds(tmp_path, "point/0", [(120, 20), (110, 20), (125, 25)])
    text = R.render(tmp_path)
    lines = text.splitlines()
    assert lines[2] == "## Summary: does PNet_3 beat PNet_0?"
    row = next(x for x in lines if x.startswith("| point | point/0 |"))
    assert "| 3 | +0.036 | +0.193 [" in row and row.endswith("| **holds** |")
    assert "| all | **pooled, 11 maps** |" in text
    assert text.index("## Summary") < text.index("## Coverage") < text.index("## Claims")


# ---------------------------------------------------------------------------
# Seed variance
# ---------------------------------------------------------------------------


def test_seed_variance_mean_and_range(tmp_path):
    for seed, n in ((0, 400), (1, 350), (2, 450)):
        s = make_summary("nlink/4", {("PNet_3", "nontrivial", True): n}, train_seed=seed)
        write_summary(tmp_path, s, seed_dir=None if seed == 0 else seed)
    # a seeds/ copy of the main run's seed counts once
    write_summary(
        tmp_path,
        make_summary("nlink/4", {("PNet_3", "nontrivial", True): 1}, train_seed=0),
        seed_dir=0,
    )
    summaries = S.load_summaries(tmp_path)
    st = {(x["model"], x["query_kind"]): x for x in R.seed_variance(summaries, "nlink/4")}
    x = st[("PNet_3", "nontrivial")]
    assert x["seeds"] == [0, 1, 2]
    assert x["success_mean"] == pytest.approx(0.8)
    assert (x["success_min"], x["success_max"]) == (0.7, 0.9)
    assert st[("PNet_0", "uniform")]["success_min"] == st[("PNet_0", "uniform")]["success_max"]
    text = R.render(tmp_path)
    assert "| PNet_3 | yes | non-trivial | 3 | 0.800 | [0.700, 0.900] |" in text
    assert (
        "Training seeds per map (the same data; `seeds/train_seed_<k>`): nlink/4 3 (0, 1, 2)."
    ) in text
    # the main tables use the main run only
    assert "| PNet_3 | 0.800 [0.760, 0.840] |" in text


def test_seed_variance_of_paired_differences(tmp_path):
    for seed, (a, b) in ((0, (40, 10)), (1, (20, 10)), (2, (30, 10))):
        s = make_summary(
            "rigid/0",
            train_seed=seed,
            comparisons=[_comp("rigid/0", "PNet_3", "PNet_0", "nontrivial", True, a, b)],
        )
        write_summary(tmp_path, s, seed_dir=None if seed == 0 else seed)
    (d,) = R.seed_variance_diffs(S.load_summaries(tmp_path), "rigid/0")
    assert d["seeds"] == [0, 1, 2] and d["diff_mean"] == pytest.approx(0.04)
    assert (d["diff_min"], d["diff_max"]) == (0.02, 0.06)
    assert d["significant"] == 2  # 40/10 and 30/10; 20/10 has p 0.099
    assert "| PNet_3 | PNet_0 | yes | non-trivial | 3 | +0.040 | [+0.020, +0.060] | 2 |" in (
        R.render(tmp_path)
    )


def test_check_seed_runs(tmp_path):
    write_summary(tmp_path, make_summary("rigid/0"))
    write_summary(tmp_path, make_summary("rigid/0", train_seed=1), seed_dir=1)
    assert S.check_seed_runs(S.load_summaries(tmp_path)) == []
    other = make_summary("rigid/0", train_seed=3)
    other["fingerprints"]["datasets"]["D1"] = "e" * 64
    write_summary(tmp_path, other, seed_dir=2)
    write_summary(tmp_path, make_summary("point/0", train_seed=1), seed_dir=1)
    probs = S.check_seed_runs(S.load_summaries(tmp_path))
    assert probs == [
        "point/point_0/seeds/train_seed_1/summary.json: no main run of point/0",
        "rigid/rigid_0/seeds/train_seed_2/summary.json: train_seed 3 but folder train_seed_2",
        "rigid/rigid_0/seeds/train_seed_2/summary.json: dataset fingerprints differ from the "
        "main run of rigid/0",
    ]
    assert "Seed-run problems: " in R.render(tmp_path)


# ---------------------------------------------------------------------------
# check_summary
# ---------------------------------------------------------------------------


def test_check_summary_accepts_paper_size_runs():
    for env in PA.MAPS:
        assert S.check_summary(make_summary(env)) == [], env


def test_check_summary_flags_sizes_and_fingerprints():
    s = make_summary("point/2")
    s["config"]["data"]["k_train"] = 600
    s["config"]["eval"]["k_test"] = 200
    s["padding"] = 0.4
    del s["fingerprints"]["datasets"]["D2"]
    s["fingerprints"]["models"] = ""
    probs = S.check_summary(s)
    assert any("K_train is 600, the paper's is 3000" in p for p in probs)
    assert any("K_test is 200, the paper's is 500" in p for p in probs)
    assert any("padding is 0.4, the paper's is 0.8" in p for p in probs)
    assert any("dataset fingerprints missing: D2" in p for p in probs)
    assert "model fingerprint missing" in probs
    s = make_summary("rigid/0")
    del s["fingerprints"]
    s["rows"] = [r for r in s["rows"] if r["steer"]]
    probs = S.check_summary(s)
    assert any("dataset fingerprints missing: D0, D1, D2, D3" in p for p in probs)
    assert any("rows missing: PNet_0 uniform without steerTo" in p for p in probs)


def test_check_summary_per_env_k_train_and_datasets():
    s = make_summary("nlink/2")
    s["config"]["data"]["k_train"] = 5000  # the nlink config's default, overridden per arm
    s["config"]["data"]["per_env"] = [{"env": "nlink/2", "k_train": 3000}]
    assert S.check_summary(s) == []
    s["config"]["data"]["per_env"] = [{"env": "nlink/2", "k_train": 4000}]
    assert S.check_summary(s) == ["K_train is 4000, the paper's is 3000"]
    s = make_summary("point/0")
    s["config"]["data"]["datasets"][3]["prune"] = False
    assert any("datasets are" in p for p in S.check_summary(s))
    s = make_summary("point/0")
    s["rows"][0]["k_test"] = 100
    assert any("rows with k_test [100]" in p for p in S.check_summary(s))
    assert S.check_summary(dict(make_summary("point/0"), env="point/9")) == [
        "env 'point/9' is not one of the paper's maps"
    ]


# ---------------------------------------------------------------------------
# write and the command line
# ---------------------------------------------------------------------------


def test_write_and_check(tmp_path, capsys):
    write_summary(tmp_path, make_summary("point/0"))
    assert "is missing" in R.check(tmp_path)
    path = R.write(tmp_path)
    assert path == tmp_path / "REPRODUCTION.md"
    assert path.read_text() == R.render(tmp_path)
    assert R.check(tmp_path) is None
    write_summary(tmp_path, make_summary("point/1"))  # new data: the document is stale
    problem = R.check(tmp_path)
    assert "\n" not in problem and "out of date" in problem and "--report-only" in problem
    assert not list(tmp_path.glob(".*tmp*"))


def test_summaries_are_not_modified(tmp_path):
    s = make_summary("point/0")
    write_summary(tmp_path, s)
    before = copy.deepcopy(s)
    R.render(tmp_path)
    assert json.loads((tmp_path / "point" / "point_0" / "summary.json").read_text()) == before


# ---------------------------------------------------------------------------
# The committed tree (issue 16)
# ---------------------------------------------------------------------------


#: every committed reproduction: the current defaults, and the earlier shortcut-path one
COMMITTED = [PAPER_ROOT, REPO / "results" / "ablations" / "shortcut_paths"]


def _committed(root):
    summaries = S.load_summaries(root)
    if not summaries:
        pytest.skip(f"no summary committed under {root} yet (scripts/reproduce.py)")
    return summaries


@pytest.mark.parametrize("root", COMMITTED, ids=lambda p: p.name)
def test_committed_reproduction_md_is_current(root):
    _committed(root)
    doc = root / R.DOC_NAME
    assert doc.exists(), (
        f"{root}/REPRODUCTION.md missing: python scripts/reproduce.py --report-only --results {root}"
    )
    assert doc.read_text(encoding="utf-8") == R.render(root), (
        f"{root}/REPRODUCTION.md is stale: python scripts/reproduce.py --report-only --results {root}"
    )


def test_the_shortcut_path_reproduction_is_complete():
    """The earlier reproduction stays whole: all 11 maps and the three seed maps."""
    summaries = S.load_summaries(COMMITTED[1])
    assert len([s for s in summaries if "seeds" not in str(s["_path"])]) == 11
    assert len([s for s in summaries if "seeds" in str(s["_path"])]) == 6


@pytest.mark.parametrize("root", COMMITTED, ids=lambda p: p.name)
def test_committed_summaries_are_paper_size(root):
    summaries = _committed(root)
    bad = {s["_path"]: p for s in summaries if (p := S.check_summary(s))}
    assert not bad, bad
    assert S.check_seed_runs(summaries) == []


def test_render_tolerates_missing_values(tmp_path):
    """summaries.py records None for a timing or fingerprint it could not read, and a
    model that solved nothing has a NaN cost ratio: the document still renders."""
    s = make_summary("point/3", {("PNet_1", "nontrivial", True): 0})
    s["timings"] = {"data": None, "train": 12.0, "eval": None}
    s["fingerprints"]["datasets"]["D3"] = None
    s["rows"][3]["cost_ratio"] = float("nan")
    write_summary(tmp_path, s)
    text = R.render(tmp_path)
    assert "| point/3 | - | 12.0 | - | 12.0 |" in text
    assert (
        "| PNet_1 | 0.800 [0.760, 0.840] | 0.958 | 1.010 | 1.069 | 0.000 [0.000, 0.040] | "
        "0.896 | - | 1.167 |"
    ) in text
    probs = S.check_summary(S.load_summaries(tmp_path)[0])
    assert "dataset fingerprints missing: D3" in probs
    assert "timings of data/train/eval missing" in probs


def test_models_fingerprint_hashes_the_weights_not_the_files(tmp_path):
    """Equal weights saved twice (Orbax files with other timestamps) fingerprint the same;
    other weights do not."""
    import time

    from ntq_jax import make_env, models
    from ntq_jax.experiment.summaries import models_fingerprint
    from ntq_jax.models import ModelConfig
    from ntq_jax.training import save_ensemble

    spec = models.ModelSpec.from_env(
        make_env("point/2"), ModelConfig(hidden=(8,), dropout_layers=1)
    )
    ens = models.init_ensemble(spec, 0, 2)
    save_ensemble(ens, tmp_path / "a" / "ensemble")
    time.sleep(1.1)
    save_ensemble(ens, tmp_path / "b" / "ensemble")
    save_ensemble(models.init_ensemble(spec, 1, 2), tmp_path / "c" / "ensemble")
    fa, fb, fc = (models_fingerprint(tmp_path / n) for n in "abc")
    assert fa == fb and fa != fc and len(fa) == 64
    assert models_fingerprint(tmp_path / "none") is None


def test_render_shows_each_maps_datasets(tmp_path):
    s = make_summary("rigid/0")
    s["datasets"] = {
        f"D{i}": {"paths": 5000, "samples": 1000 * (i + 1), "states_per_path": 14.84}
        for i in range(4)
    }
    s["config"]["planner"] = {"data_paths": 0.6}
    write_summary(tmp_path, s)
    text = R.render(tmp_path)
    assert "## Datasets" in text
    assert "| rigid/0 | 0.6 | 5000 / 1000 / 14.8 | 5000 / 2000 / 14.8 |" in text
    del s["datasets"]
    write_summary(tmp_path, s)
    assert "## Datasets" not in R.render(tmp_path)  # older summaries: no section
