"""The data-efficiency curve (scripts/learning_curve.py, ntq_jax.experiment.curve): one tiny curve on point/2.

Checks one curve row per (size, dataset, query kind), that a size's data is a
prefix of the largest size's and bit for bit what a run with that k_train
writes (grid A* is deterministic per query), that a rerun reuses the finished
sizes (no training, no planning), and that a bad size is one error line.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
from conftest import TINY_RUN

from ntq_jax import data, make_env
from ntq_jax.experiment import config as C
from ntq_jax.experiment.curve import prefix_dataset, run_curve
from ntq_jax.experiment.pipeline import load_config

ROOT = Path(__file__).resolve().parents[1]
TINY = TINY_RUN  # the suite's tiny point/2 run (conftest.py)
SIZES = [20, 40]


def _script():
    spec = importlib.util.spec_from_file_location(
        "learning_curve", ROOT / "scripts" / "learning_curve.py"
    )
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def curve(tmp_path_factory):
    out = tmp_path_factory.mktemp("curve")
    cfg = load_config(None, TINY)
    files = run_curve(cfg, "point/2", SIZES, out, progress=False, log=lambda s: None)
    return cfg, out, files


def test_one_row_per_size_dataset_kind(curve):
    _, out, files = curve
    doc = json.loads((out / "curve.json").read_text())
    keys = [(r["size"], r["dataset"], r["kind"]) for r in doc["rows"]]
    assert sorted(keys) == sorted(
        (k, f"D{i}", kind) for k in SIZES for i in range(4) for kind in ("uniform", "nontrivial")
    )
    for r in doc["rows"]:
        assert r["k_test"] == 16 and 0.0 <= r["success"] <= 1.0
        assert r["ci95"][0] <= r["success"] <= r["ci95"][1]
        assert r["rows"] > 0
    assert (out / "curve.md").is_file() and (out / "curve.png").is_file()
    by = {(r["size"], r["dataset"]): r["rows"] for r in doc["rows"]}
    for i in range(4):
        assert by[20, f"D{i}"] <= by[40, f"D{i}"]


def test_sizes_are_prefixes_and_equal_a_run_at_that_size(curve, tmp_path):
    cfg, out, _ = curve
    full = data.load_datasets(out / "data" / "point_2")
    assert all(len(d.queries) == 40 for d in full)
    small = [prefix_dataset(d, 20) for d in full]
    for s, d in zip(small, full):
        n = len(s["inputs"])
        np.testing.assert_array_equal(s["inputs"], d.inputs[:n])
        np.testing.assert_array_equal(s["targets"], d.targets[:n])
    # a run with data.k_train=20 writes exactly these datasets
    direct_cfg = load_config(None, TINY + ["data.k_train=20"])
    summ = data.generate_datasets(
        make_env("point/2"),
        C.data_options(direct_cfg, "point/2"),
        tmp_path / "d20",
        env_name="point/2",
        progress=False,
        figure=False,
    )
    for s, d in zip(small, data.load_datasets(summ["env_dir"])):
        for name in (
            "inputs",
            "targets",
            "path_index",
            "path_lengths",
            "queries",
            "query_kind",
            "solved",
        ):
            np.testing.assert_array_equal(s[name], getattr(d, name), err_msg=name)
        np.testing.assert_array_equal(s["paths"], d.paths)


def test_rerun_reuses_finished_sizes(curve):
    cfg, out, _ = curve
    ens = out / "sizes" / "20" / "models" / "ensemble" / "ensemble.json"
    res = out / "sizes" / "40" / "result.json"
    before = (ens.stat().st_mtime_ns, res.stat().st_mtime_ns)
    logs: list[str] = []
    run_curve(cfg, "point/2", SIZES, out, progress=False, log=logs.append)
    assert any("[size 20] done, reusing" in s for s in logs)
    assert any("[size 40] done, reusing" in s for s in logs)
    assert not any("train:" in s or "evaluate:" in s for s in logs)
    assert (ens.stat().st_mtime_ns, res.stat().st_mtime_ns) == before


@pytest.mark.parametrize(
    "sizes, why",
    [
        ("20,80", "larger than the config's k_train"),
        ("0,20", "not positive"),
        ("20,x", "not an integer"),
    ],
)
def test_bad_size_is_one_error_line(tmp_path, capsys, sizes, why):
    args = [
        "--sizes",
        sizes,
        "--out",
        str(tmp_path / "c"),
        "--no-progress",
        "--no-compile-cache",
    ] + [a for s in TINY for a in ("--set", s)]
    assert _script().main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and why in err[0]
    assert not (tmp_path / "c").exists()
