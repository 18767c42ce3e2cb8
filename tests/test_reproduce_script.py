"""scripts/reproduce.py: one map per resumable unit, compact summaries, seed runs on the same data.

A tiny point/2 run (the sizes of tests/test_golden.py) with one extra training
seed: the summaries' contents and fingerprints, their per-query outcomes (every
count recomputed from them), the skip of a finished map, and REPRODUCTION.md
regenerated from them (and flagged as not paper-size).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from script_loader import load_script

from ntq_jax.experiment import outcomes, reproduction, summaries

ROOT = Path(__file__).resolve().parents[1]
TINY = [
    "data.k_train=40",
    "data.gamma_queries=2000",
    "data.gamma_eval=false",
    "train.epochs=2",
    "model.hidden=[32,32]",
    "eval.k_test=16",
    "eval.n_plan=20",
    "eval.replan_rounds=2",
    "eval.replan_steps=6",
    "eval.gamma_queries=2000",
]


def _script():
    return load_script("reproduce")


def test_reproduce_one_map_with_a_training_seed(tmp_path, capsys):
    script = _script()
    runs, results = tmp_path / "runs", tmp_path / "results"
    argv = [
        "--config",
        str(ROOT / "configs" / "point_small.yaml"),
        "--env",
        "point/2",
        "--runs",
        str(runs),
        "--results",
        str(results),
        "--train-seeds",
        "1",
        "--no-progress",
        "--no-figures",
    ] + [a for s in TINY for a in ("--set", s)]
    assert script.main(argv) == 0
    main = json.loads((results / "point" / "point_2" / "summary.json").read_text())
    seed = json.loads(
        (results / "point" / "point_2" / "seeds" / "train_seed_1" / "summary.json").read_text()
    )
    assert main["env"] == seed["env"] == "point/2" and main["task"] == "point"
    assert (main["train_seed"], seed["train_seed"]) == (0, 1)
    # same data, other models; every dataset and the models fingerprinted
    assert main["fingerprints"]["datasets"] == seed["fingerprints"]["datasets"]
    assert all(main["fingerprints"]["datasets"][f"D{i}"] for i in range(4))
    assert main["fingerprints"]["models"] and (
        main["fingerprints"]["models"] != seed["fingerprints"]["models"]
    )
    assert {r["env"] for r in main["rows"]} == {"point/2"} and len(main["rows"]) == 14
    assert {(c["model"], c["baseline"]) for c in main["comparisons"]} >= {("PNet_3", "PNet_0")}
    assert main["config"]["data"]["k_train"] == 40 and main["padding"] == 0.8
    # the datasets' sizes: D3 is D2's paths with pruned samples
    ds = main["datasets"]
    assert ds == seed["datasets"] and set(ds) == {"D0", "D1", "D2", "D3"}
    assert ds["D3"]["paths"] == ds["D2"]["paths"] > 0
    assert 0 < ds["D3"]["samples"] < ds["D2"]["samples"]
    assert ds["D3"]["states_per_path"] == ds["D2"]["states_per_path"] >= 2
    assert set(main["timings"]) == {"data", "train", "eval"}
    # compact: no arrays but the per-query outcomes, from which every count is recomputed
    files = [p for p in (results / "point" / "point_2").rglob("*") if p.is_file()]
    assert sorted(p.name for p in files if p.suffix in (".npz", ".npy")) == ["outcomes.npz"] * 2
    assert sum(p.stat().st_size for p in files) < 400_000
    assert main["outcomes"] == seed["outcomes"] == "outcomes.npz"
    for d in (
        results / "point" / "point_2",
        results / "point" / "point_2" / "seeds" / "train_seed_1",
    ):
        checked, bad = outcomes.recount(d)
        assert bad == [] and checked > 14 * 10
    got = outcomes.load(results / "point" / "point_2" / "outcomes.npz")
    assert (
        got["meta"]["queries_sha256"]
        == outcomes.load(results / "point" / "point_2" / "seeds" / "train_seed_1" / "outcomes.npz")[
            "meta"
        ]["queries_sha256"]
    )  # the seeds share their test queries
    assert got[("PNet_3", "nontrivial", True)]["in_band"].shape == (16,)
    # the report: regenerated, current, and it says the sizes are not the paper's
    doc = results / "REPRODUCTION.md"
    assert doc.read_text() == reproduction.render(results)
    assert any("K_train" in p for p in summaries.check_summary(main))
    # a finished map is skipped on a rerun (nothing is planned or trained again)
    before = (results / "point" / "point_2" / "summary.json").stat().st_mtime_ns
    capsys.readouterr()
    assert script.main(argv) == 0
    out = capsys.readouterr().out
    assert out.count("summary up to date") == 2
    assert (results / "point" / "point_2" / "summary.json").stat().st_mtime_ns == before


@pytest.mark.parametrize(
    "args, msg",
    [
        ([], "--config is required"),
        (
            ["--config", str(ROOT / "configs" / "point_small.yaml"), "--env", "rigid/0"],
            "is not a map of",
        ),
        (
            ["--config", str(ROOT / "configs" / "point_small.yaml"), "--train-seeds", "a"],
            "--train-seeds",
        ),
    ],
)
def test_reproduce_usage_errors(args, msg, capsys, tmp_path):
    assert _script().main(args + ["--results", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert msg in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_report_only_with_a_corrupt_summary_or_map_options_is_one_line(tmp_path, capsys):
    script = _script()
    bad = tmp_path / "results" / "point" / "point_0" / "summary.json"
    bad.parent.mkdir(parents=True)
    bad.write_text('{"env": "point/0", ')
    assert script.main(["--report-only", "--results", str(tmp_path / "results")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "summary.json" in err[0]
    assert script.main(["--report-only", "--check", "--results", str(tmp_path / "results")]) == 2
    assert "not a readable summary" in capsys.readouterr().err
    for extra in (["--env", "point/0"], ["--train-seeds", "1"]):
        assert script.main(["--report-only", "--results", str(tmp_path / "r2")] + extra) == 2
        assert "takes no --config, --env or --train-seeds" in capsys.readouterr().err
