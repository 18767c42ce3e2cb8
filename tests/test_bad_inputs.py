"""Hostile inputs: every expected failure is one clear error, nothing is written where it must not be.

Each case asserts the message names the problem (and the fix) and that no folder
or file was written or changed where nothing should be (listings with sizes and
mtimes before and after).
"""

from __future__ import annotations

import importlib.util
import json
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _script(name):
    spec = importlib.util.spec_from_file_location(f"_bad_inputs_{name}",
                                                  ROOT / "scripts" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _listing(root: Path) -> dict:
    """``{relative path: (is dir, size, mtime_ns)}`` of everything under ``root`` (and root)."""
    root = Path(root)
    if not root.exists():
        return {}
    out = {".": (root.is_dir(), root.stat().st_size if root.is_file() else 0, 0)}
    if root.is_dir():
        for p in sorted(root.rglob("*")):
            st = p.stat()
            out[str(p.relative_to(root))] = (p.is_dir(), 0 if p.is_dir() else st.st_size,
                                             st.st_mtime_ns)
    return out


def _one_error_line(err: str, status_lines: int = 0) -> str:
    """The one ``error:`` line ending stderr (after ``status_lines`` lines of progress)."""
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 + status_lines, err
    assert lines[-1].startswith("error: ") and "Traceback" not in err, err
    return lines[-1]


# --- run folders, datasets, checkpoints, scripts ---

TINY = ["envs=[point/2]", "data.k_train=40", "data.gamma_queries=2000", "data.gamma_eval=false",
        "train.epochs=2", "model.hidden=[32,32]", "eval.k_test=16", "eval.n_plan=20",
        "eval.replan_rounds=2", "eval.replan_steps=6", "eval.gamma_queries=2000"]
SETS = sum((["--set", s] for s in TINY), [])


def _pipeline(out, extra=(), log=lambda s: None, **kw):
    from ntq_jax.pipeline import load_config, prepare_run, run_pipeline

    cfg = load_config(None, list(TINY) + list(extra))
    return run_pipeline(cfg, prepare_run(cfg, out, **kw), progress=False, figures=False, log=log)


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    """A finished tiny pipeline run (point/2); tests work on copies of it."""
    out = tmp_path_factory.mktemp("finished") / "run"
    _pipeline(out)
    return out


@pytest.fixture
def run_copy(finished_run, tmp_path):
    dst = tmp_path / "run"
    shutil.copytree(finished_run, dst)
    return dst


def _bad_out_case(tmp_path, case):
    """``(train_all.py arguments, path that must stay as it is, expected words)`` of one case."""
    if case == "unknown_env":
        return ["--out", str(tmp_path / "new"), "--set", "envs=[point/9]"], tmp_path / "new", \
            ["point/9", "unknown environment"]
    if case == "out_is_file":
        f = tmp_path / "afile"
        f.write_text("keep me")
        return ["--out", str(f)], f, ["afile", "is a file", "--out"]
    if case == "out_under_file":
        f = tmp_path / "afile"
        f.write_text("keep me")
        return ["--out", str(f / "run")], f, ["is a file", "--out"]
    if case == "read_only":
        if os.geteuid() == 0:
            pytest.skip("root writes into read-only folders")
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o555)
        return ["--out", str(ro / "run")], ro, ["not writable", "--out"]
    if case == "cpu_devices_0":
        return ["--out", str(tmp_path / "new"), "--cpu-devices", "0"], tmp_path / "new", \
            ["--cpu-devices 0", "positive"]
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
        return ["--out", str(tmp_path / "new"), "--set", "data.k_trian=3"], tmp_path / "new", \
            ["k_trian", "k_train"]
    raise AssertionError(case)


@pytest.mark.parametrize("case", ["unknown_env", "out_is_file", "out_under_file", "read_only",
                                  "cpu_devices_0", "not_a_run_folder", "overwrite_foreign_folder",
                                  "bad_config_key"])
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
    from ntq_jax.pipeline import PipelineError

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
    from ntq_jax.pipeline import PipelineError, load_config, prepare_run

    before = _listing(run_copy)
    with pytest.raises(PipelineError, match="another config"):
        _pipeline(run_copy, ["model.hidden=[16,16]"])
    assert _listing(run_copy) == before
    cfg = load_config(None, TINY + ["model.hidden=[16,16]"])
    run = prepare_run(cfg, run_copy, overwrite=True)
    assert sorted(p.name for p in run.iterdir()) == ["config.yaml", "run.json"]
    info = json.loads((run / "run.json").read_text())
    assert info == {"config_hash": cfg.hash(), "stages": {}}
    assert "- 16" in (run / "config.yaml").read_text()


def _advised_command(msg: str) -> list[str]:
    assert "regenerate it with: python scripts/generate_data.py" in msg, msg
    cmd = msg.split("regenerate it with: ", 1)[1].split(" (it rewrites", 1)[0]
    argv = shlex.split(cmd)
    return [sys.executable] + argv[1:]


def _dataset_bytes(env_dir: Path) -> dict:
    return {str(f.relative_to(env_dir)): f.read_bytes() for f in sorted(env_dir.glob("D*/*.npy"))}


def _mtimes(env_dir: Path) -> dict:
    return {str(f.relative_to(env_dir)): f.stat().st_mtime_ns
            for f in sorted(env_dir.glob("D*/*"))}


@pytest.mark.parametrize("damage", ["truncate", "flip_byte"])
def test_data_damaged_array_repaired_by_the_advised_command(run_copy, damage):
    from ntq_jax.data import DatasetError, load_datasets

    env_dir = run_copy / "data" / "point_2"
    original, mtimes = _dataset_bytes(env_dir), _mtimes(env_dir)
    f = env_dir / "D2" / "paths.npy"
    blob = f.read_bytes()
    f.write_bytes(blob[: len(blob) // 2] if damage == "truncate"
                  else blob[:-5] + bytes([blob[-5] ^ 1]) + blob[-4:])
    with pytest.raises(DatasetError) as e:
        load_datasets(env_dir)
    msg = str(e.value)
    assert "paths.npy" in msg and ("truncated" in msg or "sha256" in msg)
    proc = subprocess.run(_advised_command(msg) + ["--no-progress", "--no-figure"], cwd=ROOT,
                          capture_output=True, text=True, timeout=600,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))
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
    assert gen.main(["--config", cfg, "--out", str(run_copy / "data"), "--env", "point/2",
                     "--no-progress", "--no-figure"]) == 0
    assert "already complete (verified)" in capsys.readouterr().out
    assert {k: v for k, v in _listing(env_dir).items()} == before


def test_script_corrupt_ensemble_is_one_line_with_the_fix(run_copy):
    ens = run_copy / "models" / "point_2" / "ensemble"
    for f in sorted((ens / "params").rglob("*")):
        if f.is_file() and f.stat().st_size > 100:
            f.write_bytes(f.read_bytes()[: f.stat().st_size // 3])
    before = _listing(run_copy)
    proc = subprocess.run([sys.executable, str(ROOT / "scripts" / "train_all.py"), "--out",
                           str(run_copy), "--no-progress", "--no-figures", "--no-compile-cache"]
                          + SETS, capture_output=True, text=True, timeout=600,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert proc.returncode == 2, proc.stderr
    line = _one_error_line(proc.stderr)
    assert str(ens) in line and "delete" in line and "rerun" in line, line
    assert "Event loop is closed" not in proc.stderr
    after = _listing(run_copy)
    assert {k: v for k, v in after.items() if not k.startswith("run.json")} == \
        {k: v for k, v in before.items() if not k.startswith("run.json")}
    # the advised fix works: delete the folder and rerun
    shutil.rmtree(ens)
    _pipeline(run_copy)
    assert (ens / "ensemble.json").is_file()


def test_script_train_on_damaged_data_is_one_line(run_copy, tmp_path, capsys):
    env_dir = run_copy / "data" / "point_2"
    f = env_dir / "D1" / "queries.npy"
    f.write_bytes(f.read_bytes()[:40])
    out = tmp_path / "pnets"
    assert _script("train").main(["--data", str(env_dir), "--out", str(out), "--no-progress"]
                                 + SETS) == 2
    line = _one_error_line(capsys.readouterr().err, status_lines=1)  # "training ... on ..."
    assert "D1/queries.npy" in line and "scripts/generate_data.py --config" in line
    assert not out.exists()


@pytest.mark.parametrize("case", ["gen_unknown_env", "gen_missing_config", "gen_out_is_file",
                                  "train_no_env_json", "train_cpu_devices_0",
                                  "export_unknown_env", "export_out_under_file",
                                  "export_no_name"])
def test_script_expected_errors_are_one_line(tmp_path, capsys, case):
    afile = tmp_path / "afile"
    afile.write_text("keep")
    script, args, words = {
        "gen_unknown_env": ("generate_data", ["--env", "point/9", "--out", str(tmp_path / "d")],
                            ["point/9"]),
        "gen_missing_config": ("generate_data", ["--config", str(tmp_path / "no.yaml")],
                               ["no.yaml", "not found"]),
        "gen_out_is_file": ("generate_data", ["--env", "point/0", "--out", str(afile)],
                            ["afile", "folder"]),
        "train_no_env_json": ("train", ["--data", str(tmp_path), "--out", str(tmp_path / "o")],
                              ["--data", "env.json"]),
        "train_cpu_devices_0": ("train", ["--data", str(tmp_path), "--cpu-devices", "0"],
                                ["--cpu-devices 0"]),
        "export_unknown_env": ("export_env", ["point/9"], ["point/9"]),
        "export_out_under_file": ("export_env", ["point/0", "--out", str(afile / "x.json")],
                                  ["afile", "folder"]),
        "export_no_name": ("export_env", [], ["preset name"]),
    }[case]
    before = _listing(tmp_path)
    assert _script(script).main(args) == 2
    line = _one_error_line(capsys.readouterr().err)
    for w in words:
        assert w in line, (w, line)
    assert _listing(tmp_path) == before


def test_script_unexpected_errors_keep_their_traceback():
    from ntq_jax.cli import run_cli

    def bug():
        raise KeyError("a bug")

    with pytest.raises(KeyError):
        run_cli(bug)
