"""results/panda/REPRODUCTION.md from synthetic Panda summaries (ntq_jax.experiment.panda_page).

Hand-made summaries in the shape of a run's results.json rows and comparisons: a scene
where PNet_3 beats PNet_0 in every seed (the verdict holds), one where the seeds disagree
(unresolved), the pooled row, Holm's adjustment, the per-model table, the benchmark
problems' table, and the dispatch of ``reproduction.write``/``check`` to this page.
"""

import json
from pathlib import Path

from ntq_jax.experiment import panda_page as P
from ntq_jax.experiment import reproduction as R
from ntq_jax.stats import mcnemar_exact

K = 500
KINDS = ("uniform", "nontrivial")


def _row(env, model, kind, successes):
    return {
        "task": "panda",
        "env": env,
        "model": model,
        "query_kind": kind,
        "steer": True,
        "gamma_nt": 0.42,
        "k_test": K,
        "successes": successes,
        "success_ratio": successes / K,
        "cost_ratio": 1.1,
    }


def _comp(env, kind, only_a, only_b):
    return {
        "env": env,
        "steer": True,
        "query_kind": kind,
        "model": "PNet_3",
        "baseline": "PNet_0",
        "n": K,
        "both": 300,
        "only_a": only_a,
        "only_b": only_b,
        "neither": K - 300 - only_a - only_b,
        "success_diff": (only_a - only_b) / K,
        "mcnemar_p": mcnemar_exact(only_a, only_b),
    }


def _summary(root, env, seed, only_a, only_b):
    slug = env.replace("/", "_")
    rows = [_row(env, f"PNet_{m}", k, 350 + 10 * m + seed) for m in range(4) for k in KINDS]
    s = {
        "schema": 1,
        "task": "panda",
        "env": env,
        "env_slug": slug,
        "seed": 0,
        "train_seed": seed,
        "config_hash": "0" * 16,
        "rows": rows,
        "comparisons": [_comp(env, k, only_a, only_b) for k in KINDS],
        "datasets": {"D0": {"states_per_path": 6.4}, "D3": {"samples": 12345}},
        "timings": {"data": 170.0, "train": 900.0, "eval": 300.0},
        "command": "python scripts/reproduce.py --config configs/panda.yaml",
    }
    d = Path(root) / "panda" / slug
    if seed:
        d = d / "seeds" / f"train_seed_{seed}"
    d.mkdir(parents=True, exist_ok=True)
    (d / "summary.json").write_text(json.dumps(s))
    return d


def _line(text, start):
    """The cells of the first line that starts with ``start``."""
    line = next(x for x in text.splitlines() if x.startswith(start))
    return [c.strip() for c in line.strip("|").split("|")]


def test_the_page_judges_each_scene_and_the_pool(tmp_path):
    for seed, (a, b) in enumerate([(60, 10), (55, 12), (58, 9)]):
        _summary(tmp_path, "panda/table_pick/1", seed, a, b)
    for seed, (a, b) in enumerate([(30, 10), (10, 30), (20, 21)]):
        _summary(tmp_path, "panda/cage/1", seed, a, b)
    text = P.render(tmp_path)
    assert text == P.render(tmp_path)  # deterministic
    tp = _line(text, "| panda/table_pick/1 | 3 |")
    assert tp[2] == f"{(60 + 55 + 58 - 31) / 3 / K:+.3f}" and tp[-1] == "holds"
    cage = _line(text, "| panda/cage/1 | 3 |")
    assert cage[-1] == "unresolved"
    pooled = _line(text, "| 2 scenes, pooled |")
    assert pooled[1] == "6"
    p_raw, p_holm = float(tp[5].replace("<", "")), float(tp[6].replace("<", ""))
    assert p_holm >= p_raw
    # the per-model table: the mean over the seeds and its range
    assert "| PNet_3 | 0.762 [0.760, 0.764] |" in text


def test_problems_rows_and_the_dispatch_of_reproduction(tmp_path):
    d = _summary(tmp_path, "panda/cage/1", 0, 30, 10)
    rate = lambda k: {"solved": k, "of": 99, "ratio": k / 99, "ci95": [0, 1]}  # noqa: E731
    (d / "problems.json").write_text(
        json.dumps(
            {
                "valid": 99,
                "neural_median_seconds": 0.05,
                "models": {
                    **{f"PNet_{m}": rate(40 + m) for m in range(4)},
                    "PNet_best-of-4": rate(60),
                },
                "peers": {
                    "rrtconnect": {
                        "solved": rate(99),
                        "certified": rate(70),
                        "median_solve_seconds": 0.04,
                    }
                },
            }
        )
    )
    path = R.write(tmp_path)
    text = path.read_text()
    assert text.startswith("# Beyond the paper: a 7-DoF arm")
    row = _line(text, "| panda/cage/1 | 0 | 99 |")
    assert row[3:8] == ["0.404", "0.414", "0.424", "0.434", "0.606"]
    assert row[8:12] == ["50.00", "1.000", "0.707", "40.00"]  # times in ms
    assert row[12:] == ["not built", "", ""]  # VAMP: no entry in this problems.json
    got = json.loads((d / "problems.json").read_text())
    got["peers"]["vamp"] = {"solved": rate(98), "certified": rate(30), "median_solve_seconds": 5e-4}
    (d / "problems.json").write_text(json.dumps(got))
    row = _line(R.write(tmp_path).read_text(), "| panda/cage/1 | 0 | 99 |")
    assert row[9:] == ["1.000", "0.707", "40.00", "0.990", "0.303", "0.50"]
    assert R.check(tmp_path) is None
    path.write_text(text + "edited\n")
    assert "out of date" in R.check(tmp_path)


def test_the_committed_page_is_current():
    """results/panda/REPRODUCTION.md is what the committed summaries give."""
    root = Path(__file__).resolve().parent.parent / "results" / "panda"
    assert R.check(root) is None
