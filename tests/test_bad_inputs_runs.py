"""Hostile inputs, run folders, configs and datasets: train_all's --out and --set, run.json,
--overwrite, damaged datasets and checkpoints, a full disk.

Every expected failure is one clear error, nothing is written where it must not be
(split from tests/test_bad_inputs.py by the surface each test probes; the shared
helpers are in bad_inputs_common.py).
"""

from __future__ import annotations

import json
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from bad_inputs_common import ROOT, TINY, _listing, _one_error_line, _script

SETS = sum((["--set", s] for s in TINY), [])


def _pipeline(out, extra=(), log=lambda s: None, **kw):
    from ntq_jax.experiment.pipeline import load_config, prepare_run, run_pipeline

    cfg = load_config(None, list(TINY) + list(extra))
    return run_pipeline(cfg, prepare_run(cfg, out, **kw), progress=False, figures=False, log=log)


@pytest.fixture(scope="module")
def finished_run(tiny_run):
    """A finished tiny pipeline run (point/2; the session's, conftest.py, figures included):
    read only, tests work on copies of it."""
    assert tiny_run.config == TINY
    return tiny_run.path


@pytest.fixture
def run_copy(finished_run, tmp_path):
    dst = tmp_path / "run"
    shutil.copytree(finished_run, dst)
    return dst


def _bad_out_case(tmp_path, case):
    """``(train_all.py arguments, path that must stay as it is, expected words)`` of one case."""
    if case == "unknown_env":
        return (
            ["--out", str(tmp_path / "new"), "--set", "envs=[point/9]"],
            tmp_path / "new",
            ["point/9", "unknown environment"],
        )
    if case == "out_is_file":
        f = tmp_path / "afile"
        f.write_text("keep me")
        return ["--out", str(f)], f, ["afile", "is a file", "--out"]
    if case == "out_under_file":
        f = tmp_path / "afile"
        f.write_text("keep me")
        return ["--out", str(f / "run")], f, ["is a file", "--out"]
    if case == "read_only":
        if os.geteuid() == 0:  # root writes into a mode-555 folder: use a read-only file system
            assert Path("/proc").is_dir()
            return (
                ["--out", "/proc/ntq_jax_run"],
                tmp_path / "new",
                ["/proc/ntq_jax_run", "creating a file in /proc failed", "writable place"],
            )
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o555)
        return ["--out", str(ro / "run")], ro, ["Permission denied", "--out", "writable place"]
    if case == "cpu_devices_0":
        return (
            ["--out", str(tmp_path / "new"), "--cpu-devices", "0"],
            tmp_path / "new",
            ["--cpu-devices 0", "positive"],
        )
    if case == "not_a_run_folder":
        d = tmp_path / "mine"
        d.mkdir()
        (d / "notes.txt").write_text("mine")
        return ["--out", str(d)], d, ["not a run folder", "run.json", "--out", "--overwrite"]
    if case == "overwrite_foreign_folder":
        d = tmp_path / "mine"
        d.mkdir()
        (d / "notes.txt").write_text("mine")
        return ["--out", str(d), "--overwrite"], d, ["notes.txt", "refuses to delete"]
    if case == "bad_config_key":
        return (
            ["--out", str(tmp_path / "new"), "--set", "data.k_trian=3"],
            tmp_path / "new",
            ["k_trian", "k_train"],
        )
    if case == "bad_set_yaml":
        return (
            ["--out", str(tmp_path / "new"), "--set", "data.k_train=[1,"],
            tmp_path / "new",
            ["data.k_train=[1,", "not valid YAML", "quote"],
        )
    if case == "binary_config":
        f = tmp_path / "bin.yaml"
        f.write_bytes(bytes(range(256)))
        return (
            ["--out", str(tmp_path / "new"), "--config", str(f)],
            tmp_path / "new",
            ["bin.yaml", "not a text"],
        )
    if case == "per_env_typo":
        return (
            ["--out", str(tmp_path / "new"), "--set", "data.per_env=[{env: point/9, k_train: 5}]"],
            tmp_path / "new",
            ["data.per_env[0].env", "point/9", "not an environment"],
        )
    if case == "visgraph_rigid":
        return (
            [
                "--out",
                str(tmp_path / "new"),
                "--set",
                "envs=[rigid/0]",
                "--set",
                "planner.name=visgraph",
                "--set",
                "planner.per_env=[]",
            ],
            tmp_path / "new",
            ["planner.name visgraph", "point robot only", "roadmap"],
        )
    if case == "astar_arm":
        return (
            [
                "--out",
                str(tmp_path / "new"),
                "--set",
                "envs=[point/0, nlink/6]",
                "--set",
                "planner.per_env=[{env: nlink/6, name: astar}]",
            ],
            tmp_path / "new",
            ["planner.per_env astar for nlink/6", "2-D configuration space"],
        )
    raise AssertionError(case)


@pytest.mark.parametrize(
    "case",
    [
        "unknown_env",
        "out_is_file",
        "out_under_file",
        "read_only",
        "cpu_devices_0",
        "not_a_run_folder",
        "overwrite_foreign_folder",
        "bad_config_key",
        "visgraph_rigid",
        "astar_arm",
        "bad_set_yaml",
        "binary_config",
        "per_env_typo",
    ],
)
def test_run_bad_out_or_config_is_one_error_and_writes_nothing(tmp_path, capsys, case):
    args, keep, words = _bad_out_case(tmp_path, case)
    before = _listing(tmp_path)
    assert _script("train_all").main(SETS + args + ["--no-progress", "--no-compile-cache"]) == 2
    line = _one_error_line(capsys.readouterr().err)
    for w in words:
        assert w in line, (w, line)
    assert _listing(tmp_path) == before  # nothing created, nothing changed
    assert keep.exists() == (keep.name != "new")


@pytest.mark.parametrize("damage", ["deleted", "corrupt", "not_a_record"])
def test_run_folder_without_valid_run_json_is_refused_with_another_config(run_copy, damage):
    from ntq_jax.experiment.pipeline import PipelineError

    f = run_copy / "run.json"
    if damage == "deleted":
        f.unlink()
    elif damage == "corrupt":
        f.write_text(f.read_text()[:20])
    else:
        f.write_text("[1, 2]")
    config_before = (run_copy / "config.yaml").read_text()
    before = _listing(run_copy)
    for other in (["model.hidden=[16,16]"], ["data.k_train=30"], []):
        with pytest.raises(PipelineError, match="not a run folder") as e:
            _pipeline(run_copy, other)
        assert "run.json" in str(e.value) and "--overwrite" in str(e.value)
    assert _listing(run_copy) == before
    assert (run_copy / "config.yaml").read_text() == config_before


def test_run_foreign_config_refused_and_overwrite_starts_over(run_copy, capsys):
    from ntq_jax.experiment.pipeline import PipelineError, load_config, prepare_run

    before = _listing(run_copy)
    with pytest.raises(PipelineError, match="another config"):
        _pipeline(run_copy, ["model.hidden=[16,16]"])
    assert _listing(run_copy) == before
    cfg = load_config(None, TINY + ["model.hidden=[16,16]"])
    run = prepare_run(cfg, run_copy, overwrite=True)
    assert sorted(p.name for p in run.iterdir()) == [".lock", "config.yaml", "run.json"]
    info = json.loads((run / "run.json").read_text())
    assert info == {"config_hash": cfg.hash(), "stages": {}}
    assert "- 16" in (run / "config.yaml").read_text()


@pytest.mark.parametrize(
    "mine",
    [
        "figures/mine.txt",
        "models/point_2/notes.md",
        "data/point_2/my_queries.csv",
        "data/point_2/D0/keep.npy",
        "paths/point_2/analysis/out.txt",
    ],
)
def test_overwrite_never_deletes_a_users_file_in_a_subfolder(run_copy, mine):
    """--overwrite checks the whole tree against what a run writes before deleting anything."""
    from ntq_jax.experiment.pipeline import PipelineError, foreign_files, load_config, prepare_run

    assert foreign_files(run_copy) == []  # every file a run writes is known as one
    (run_copy / mine).parent.mkdir(parents=True, exist_ok=True)
    (run_copy / mine).write_text("a user's file")
    before = _listing(run_copy)
    cfg = load_config(None, TINY + ["model.hidden=[16,16]"])
    with pytest.raises(PipelineError, match="refuses to delete") as e:
        prepare_run(cfg, run_copy, overwrite=True)
    assert mine in str(e.value)
    assert _listing(run_copy) == before and (run_copy / mine).read_text() == "a user's file"


def _advised_command(msg: str) -> list[str]:
    assert "regenerate it with: python scripts/generate_data.py" in msg, msg
    cmd = msg.split("regenerate it with: ", 1)[1].split(" (it rewrites", 1)[0]
    argv = shlex.split(cmd)
    return [sys.executable] + argv[1:]


def _dataset_bytes(env_dir: Path) -> dict:
    return {str(f.relative_to(env_dir)): f.read_bytes() for f in sorted(env_dir.glob("D*/*.npy"))}


def _mtimes(env_dir: Path) -> dict:
    return {str(f.relative_to(env_dir)): f.stat().st_mtime_ns for f in sorted(env_dir.glob("D*/*"))}


@pytest.mark.parametrize("damage", ["truncate", "flip_byte"])
def test_data_damaged_array_repaired_by_the_advised_command(run_copy, damage, script):
    from ntq_jax.data import DatasetError, load_datasets

    env_dir = run_copy / "data" / "point_2"
    original, mtimes = _dataset_bytes(env_dir), _mtimes(env_dir)
    f = env_dir / "D2" / "paths.npy"
    blob = f.read_bytes()
    f.write_bytes(
        blob[: len(blob) // 2]
        if damage == "truncate"
        else blob[:-5] + bytes([blob[-5] ^ 1]) + blob[-4:]
    )
    with pytest.raises(DatasetError) as e:
        load_datasets(env_dir)
    msg = str(e.value)
    assert "paths.npy" in msg and ("truncated" in msg or "sha256" in msg)
    argv = _advised_command(msg) + ["--no-progress", "--no-figure"]
    if damage == "truncate":  # the command as a user types it, in a new interpreter
        proc = subprocess.run(
            argv,
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=600,
            env=dict(os.environ, PYTHONPATH=str(ROOT)),
        )
    else:  # the same script's main in this process (its compiled programs are this run's)
        proc = script("generate_data", *argv[2:])
    assert proc.returncode == 0, proc.stderr
    assert "already complete" not in proc.stdout and "D2: damaged" in proc.stdout
    assert _dataset_bytes(env_dir) == original
    after = _mtimes(env_dir)
    changed = {k for k in after if after[k] != mtimes[k]}
    assert changed and all(k.startswith("D2/") for k in changed), changed
    load_datasets(env_dir)  # verified again


def test_data_finished_run_notices_and_repairs_a_damaged_dataset(run_copy):
    env_dir = run_copy / "data" / "point_2"
    original = _dataset_bytes(env_dir)
    f = env_dir / "D0" / "inputs.npy"
    f.write_bytes(f.read_bytes()[:-8])
    lines = []
    _pipeline(run_copy, log=lines.append)
    assert any("D0 failed verification" in ln and "inputs.npy" in ln for ln in lines), lines
    assert _dataset_bytes(env_dir) == original


def test_data_complete_means_verified(run_copy):
    from ntq_jax.data.format import damaged_datasets, dataset_problem

    env_dir = run_copy / "data" / "point_2"
    names = ["D0", "D1", "D2", "D3"]
    assert damaged_datasets(env_dir, names) == {}
    f = env_dir / "D1" / "targets.npy"
    blob = f.read_bytes()
    f.write_bytes(blob[:-1] + bytes([blob[-1] ^ 0x10]))  # same size: only the checksum sees it
    assert dataset_problem(env_dir / "D1", checksum=False) is None
    assert "sha256" in dataset_problem(env_dir / "D1")
    f.write_bytes(blob + b"\0")
    assert "truncated or corrupt" in dataset_problem(env_dir / "D1", checksum=False)
    assert set(damaged_datasets(env_dir, names)) == {"D1"}


def test_data_generate_script_says_complete_only_when_verified(run_copy, capsys):
    env_dir = run_copy / "data" / "point_2"
    cfg = str(env_dir / "config.yaml")
    before = _listing(env_dir)
    gen = _script("generate_data")
    assert (
        gen.main(
            [
                "--config",
                cfg,
                "--out",
                str(run_copy / "data"),
                "--env",
                "point/2",
                "--no-progress",
                "--no-figure",
            ]
        )
        == 0
    )
    assert "already complete (verified)" in capsys.readouterr().out
    assert {k: v for k, v in _listing(env_dir).items()} == before


def test_script_corrupt_ensemble_is_one_line_with_the_fix(run_copy):
    ens = run_copy / "models" / "point_2" / "ensemble"
    for f in sorted((ens / "params").rglob("*")):
        if f.is_file() and f.stat().st_size > 100:
            f.write_bytes(f.read_bytes()[: f.stat().st_size // 3])
    before = _listing(run_copy)
    proc = subprocess.run(
        [
            sys.executable,
            str(ROOT / "scripts" / "train_all.py"),
            "--out",
            str(run_copy),
            "--no-progress",
            "--no-figures",
            "--no-compile-cache",
        ]
        + SETS,
        capture_output=True,
        text=True,
        timeout=600,
        env=dict(os.environ, PYTHONPATH=str(ROOT)),
    )
    assert proc.returncode == 2, proc.stderr
    line = _one_error_line(proc.stderr)
    assert str(ens) in line and "delete" in line and "rerun" in line, line
    assert "Event loop is closed" not in proc.stderr
    after = _listing(run_copy)
    kept = lambda d: {k: v for k, v in d.items() if k not in ("run.json", ".lock")}  # noqa: E731
    assert kept(after) == kept(before)  # the run took its lock and recorded its stages only
    # the advised fix works: delete the folder and rerun
    shutil.rmtree(ens)
    _pipeline(run_copy)
    assert (ens / "ensemble.json").is_file()


def test_script_train_on_damaged_data_is_one_line(run_copy, tmp_path, capsys):
    env_dir = run_copy / "data" / "point_2"
    f = env_dir / "D1" / "queries.npy"
    f.write_bytes(f.read_bytes()[:40])
    out = tmp_path / "pnets"
    assert (
        _script("train").main(["--data", str(env_dir), "--out", str(out), "--no-progress"] + SETS)
        == 2
    )
    line = _one_error_line(capsys.readouterr().err, status_lines=1)  # "training ... on ..."
    assert "D1/queries.npy" in line and "scripts/generate_data.py --config" in line
    assert not out.exists()


def test_a_full_disk_during_train_all_is_one_line_and_the_run_resumes(
    run_copy, capsys, monkeypatch
):
    """ENOSPC while writing (also wrapped by a library, as Orbax does) is one line naming the
    file and the fix; nothing half-written is left, and the same command then finishes."""
    from ntq_jax import artifacts

    real = artifacts.replace
    calls = {"n": 0}
    (run_copy / "results.json").unlink()

    def full(tmp, dst):
        if Path(dst).name == "results.json":
            calls["n"] += 1
            os.unlink(tmp)
            err = OSError(28, "No space left on device", str(dst))
            raise RuntimeError("a library's wrapper of the write") from err
        return real(tmp, dst)

    monkeypatch.setattr(artifacts, "replace", full)
    argv = SETS + ["--out", str(run_copy), "--no-progress", "--no-figures", "--no-compile-cache"]
    assert _script("train_all").main(argv) == 2
    line = _one_error_line(capsys.readouterr().err)
    assert calls["n"] == 1 and "results.json: no space left on device" in line, line
    assert "free some space and run the same command again" in line, line
    assert not list(run_copy.rglob(".*.tmp-*")) and not (run_copy / "results.json").exists()
    monkeypatch.setattr(artifacts, "replace", real)
    assert _script("train_all").main(argv) == 0
    assert (run_copy / "results.json").is_file()
    out = capsys.readouterr().out  # the end of a run: a headline per map, not every table
    assert "PNet_3 - PNet_0, non-trivial: " in out and f"{run_copy / 'tables.md'}" in out
    assert "| PNet_0 |" not in out
