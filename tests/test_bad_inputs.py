"""Hostile inputs: every expected failure is one clear error, nothing is written where it must not be.

Each case asserts the message names the problem (and the fix) and that no folder
or file was written or changed where nothing should be (listings with sizes and
mtimes before and after).
"""

from __future__ import annotations

import json
import os
import time
import shlex
import signal
import shutil
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ntq_jax as nj
from ntq_jax.envs import env_slug, resolve_envs
from ntq_jax.envs import MAX_STATES_PER_MOTION, EnvError
from ntq_jax.presets import PRESETS

from script_loader import load_script

ROOT = Path(__file__).resolve().parents[1]


def _script(name):
    return load_script(name, f"_bad_inputs_{name}")


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
        if os.geteuid() == 0:  # root writes into a mode-555 folder: use a read-only file system
            assert Path("/proc").is_dir()
            return ["--out", "/proc/ntq_jax_run"], tmp_path / "new", \
                ["/proc/ntq_jax_run", "creating a file in /proc failed", "writable place"]
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o555)
        return ["--out", str(ro / "run")], ro, ["Permission denied", "--out", "writable place"]
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
    if case == "bad_set_yaml":
        return ["--out", str(tmp_path / "new"), "--set", "data.k_train=[1,"], \
            tmp_path / "new", ["data.k_train=[1,", "not valid YAML", "quote"]
    if case == "binary_config":
        f = tmp_path / "bin.yaml"
        f.write_bytes(bytes(range(256)))
        return ["--out", str(tmp_path / "new"), "--config", str(f)], tmp_path / "new", \
            ["bin.yaml", "not a text"]
    if case == "per_env_typo":
        return ["--out", str(tmp_path / "new"), "--set",
                "data.per_env=[{env: point/9, k_train: 5}]"], tmp_path / "new", \
            ["data.per_env[0].env", "point/9", "not an environment"]
    if case == "visgraph_rigid":
        return ["--out", str(tmp_path / "new"), "--set", "envs=[rigid/0]", "--set",
                "planner.name=visgraph", "--set", "planner.per_env=[]"], tmp_path / "new", \
            ["planner.name visgraph", "point robot only", "roadmap"]
    if case == "astar_arm":
        return ["--out", str(tmp_path / "new"), "--set", "envs=[point/0, nlink/6]", "--set",
                "planner.per_env=[{env: nlink/6, name: astar}]"], tmp_path / "new", \
            ["planner.per_env astar for nlink/6", "2-D configuration space"]
    raise AssertionError(case)


@pytest.mark.parametrize("case", ["unknown_env", "out_is_file", "out_under_file", "read_only",
                                  "cpu_devices_0", "not_a_run_folder", "overwrite_foreign_folder",
                                  "bad_config_key", "visgraph_rigid", "astar_arm",
                                  "bad_set_yaml", "binary_config", "per_env_typo"])
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


@pytest.mark.parametrize("mine", ["figures/mine.txt", "models/point_2/notes.md",
                                  "data/point_2/my_queries.csv", "data/point_2/D0/keep.npy",
                                  "paths/point_2/analysis/out.txt"])
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
    return {str(f.relative_to(env_dir)): f.stat().st_mtime_ns
            for f in sorted(env_dir.glob("D*/*"))}


@pytest.mark.parametrize("damage", ["truncate", "flip_byte"])
def test_data_damaged_array_repaired_by_the_advised_command(run_copy, damage, script):
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
    argv = _advised_command(msg) + ["--no-progress", "--no-figure"]
    if damage == "truncate":  # the command as a user types it, in a new interpreter
        proc = subprocess.run(argv, cwd=ROOT, capture_output=True, text=True, timeout=600,
                              env=dict(os.environ, PYTHONPATH=str(ROOT)))
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
    from ntq_jax.experiment.cli import run_cli

    def bug():
        raise KeyError("a bug")

    with pytest.raises(KeyError):
        run_cli(bug)


def _tree(path: Path) -> dict[str, bytes]:
    """Every file under ``path`` with its bytes (to assert that nothing was written or changed)."""
    return {str(p.relative_to(path)): p.read_bytes() for p in sorted(path.rglob("*")) if p.is_file()}


# --- maps and environments ----------------------------------------------------------

_POINT_MAP = {"name": "m", "robot": {"kind": "point"}, "bounds": [[0, 10], [0, 10]],
              "boxes": [[5, 5, 1, 1]], "discs": [[2, 2, 0.5]], "padding": 0.1}
_ARM = {"kind": "nlink", "link_lengths": [2.0, 2.0], "base": [5.0, 5.0], "resolution": 0.02}
_RIGID = {"kind": "rigid_body", "length": 1.2, "width": 0.4, "angle_weight": 0.5,
          "resolution": 0.05}


@pytest.mark.parametrize("patch, match", [
    # rows of the wrong width are refused, never reshaped into other geometry
    ({"discs": [[1, 2, 1, 1], [5, 5, 1, 1], [3, 3, 1, 1]]},
     r"discs\[0\] is \[1, 2, 1, 1\] \(4 numbers\): expected \[cx, cy, r\] \(3 numbers\)"),
    ({"boxes": [[1, 2, 1, 1, 3, 3]]},
     r"boxes\[0\] is \[1, 2, 1, 1, 3, 3\] \(6 numbers\): expected \[cx, cy, half_w, half_h\]"),
    ({"boxes": [5, 5, 1, 1]},
     r"boxes\[0\] is 5, not a row: expected a list of rows \[cx, cy, half_w, half_h\]"),
    ({"boxes": [[5, 5, 1, 1], [1, 2, 3]]},
     r"boxes\[1\] is \[1, 2, 3\] \(3 numbers\): expected \[cx, cy, half_w, half_h\] \(4 numbers\)"),
    ({"boxes": None}, r"boxes must be a list of rows \[cx, cy, half_w, half_h\].*got null"),
    ({"bounds": [[0, 10, 20], [0, 10]]}, r"bounds\[0\] is \[0, 10, 20\].*expected \[min, max\]"),
    ({"bounds": [0, 10, 0, 10]}, r"bounds\[0\] is 0, not a row"),
    # entries are numbers: not bools, not strings
    ({"boxes": [[5, "5", 1, 1]]}, r"boxes\[0\] is \[5, '5', 1, 1\]: '5' is not a finite number"),
    ({"discs": [[2, 2, True]]}, r"discs\[0\] is \[2, 2, True\]: True is not a finite number"),
    ({"padding": True}, r"padding must be a number >= 0, got True \(bool\)"),
    ({"padding": "0.5"}, r"padding must be a number >= 0, got '0.5' \(str\)"),
    ({"name": None}, r"name must be a non-empty string, got None"),
    ({"robot": {**_ARM, "link_lengths": "22"}},
     r"robot: nlink.link_lengths must be a list \[l1, l2, \.\.\.\].*got '22' \(str\)"),
    ({"robot": {**_ARM, "base": "55"}},
     r"robot: nlink.base must be a list \[x, y\] \(2 numbers\), got '55' \(str\)"),
    ({"robot": {**_ARM, "base": [1, 2, 3]}}, r"nlink.base is \[1, 2, 3\]: expected \[x, y\]"),
    ({"robot": {**_ARM, "link_lengths": [2, False]}}, r"nlink.link_lengths\[1\] is False"),
    ({"robot": {**_RIGID, "length": True}}, r"rigid_body.length must be a number > 0, got True"),
    ({"robot": {**_RIGID, "resolution": None}}, r"rigid_body.resolution must be a number > 0"),
    ({"robot": {"kind": ["point"]}}, r"robot.kind \['point'\] is unknown"),
    # bounded discretisation: no resolution that makes one motion check millions of states
    ({"robot": {**_RIGID, "resolution": 1e-9}},
     (r"rigid_body.resolution 1e-09 is too fine: the longest motion \(15.71\).*1.57e\+10 states; "
      r"use resolution >= 0.000157 \(at most 100000 states per motion\)")),
    ({"robot": {**_ARM, "resolution": 1e-7}},
     r"nlink.resolution 1e-07 rad is too fine.*use resolution >= 8.89e-05 rad"),
])
def test_map_bad_field_is_one_error_naming_key_row_and_form(tmp_path, patch, match):
    f = tmp_path / "m.json"
    f.write_text(json.dumps({**_POINT_MAP, **patch}))
    before = _tree(tmp_path)
    with pytest.raises(EnvError, match=match) as e:
        nj.make_env(str(f))
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(f"environment file {str(f)!r}: ")
    assert _tree(tmp_path) == before  # nothing written or changed


def test_map_good_rows_still_load_exactly(tmp_path):
    """The strict parser keeps every valid form: lists, tuples, NumPy rows, empty lists."""
    env = nj.Env.from_json({**_POINT_MAP, "boxes": [(5, 5, 1, 1), np.array([8, 8, 0.5, 0.5])],
                            "discs": [], "padding": 0})
    assert np.asarray(env.world.boxes).tolist() == [[5, 5, 1, 1], [8, 8, 0.5, 0.5]]
    assert env.world.discs.shape == (0, 3) and env.padding == 0.0
    arm = nj.Env.from_json({**_POINT_MAP, "robot": _ARM})
    assert arm.robot.link_lengths == (2.0, 2.0) and arm.robot.base == (5.0, 5.0)


def test_map_directory_is_reported_as_a_directory(tmp_path):
    folder = tmp_path / "some" / "folder"
    folder.mkdir(parents=True)
    with pytest.raises(EnvError, match=r"is a directory, not a JSON map file"):
        nj.make_env(str(folder))
    (tmp_path / "dir.json").mkdir()
    with pytest.raises(EnvError, match=r"'.*dir\.json' is a directory"):
        nj.make_env(str(tmp_path / "dir.json"))
    with pytest.raises(EnvError, match=r"does not exist"):
        nj.make_env(str(tmp_path / "none.json"))


def test_map_resolution_floor_bounds_the_work_of_steer_to():
    """At the finest allowed resolution three workspace-long motions finish quickly, and every
    preset and every config in configs/ still loads."""
    longest = 10 * np.sqrt(2) + 0.5 * np.pi
    floor = longest / MAX_STATES_PER_MOTION
    with pytest.raises(EnvError, match="too fine"):
        nj.Env.from_json({**_POINT_MAP, "robot": {**_RIGID, "resolution": floor * 0.99}})
    env = nj.Env.from_json({**_POINT_MAP, "boxes": [], "discs": [],
                            "robot": {**_RIGID, "resolution": floor * 1.01}})
    a = np.array([[1, 1, 0], [1, 9, 3], [9, 1, -3]], np.float32)
    b = np.array([[9, 9, 3], [9, 1, 0], [1, 9, 0]], np.float32)
    env.steer_to(a[:1], b[:1]).block_until_ready()  # compile
    t0 = time.perf_counter()
    free = np.asarray(env.steer_to(a, b))
    assert time.perf_counter() - t0 < 30  # minutes before the bound (resolution 1e-9)
    assert free.tolist() == [True, True, True]
    for name in PRESETS:
        nj.make_env(name)
    from ntq_jax.experiment.pipeline import load_config
    for f in sorted((ROOT / "configs").glob("*.yaml")):
        resolve_envs(load_config(f, []).envs)


def _wrap64(theta32: np.ndarray) -> np.ndarray:
    """The exact float32 angles wrapped to [-pi, pi) in float64, then rounded to float32."""
    t = theta32.astype(np.float64)
    r = t - 2 * np.pi * np.round(t / (2 * np.pi))
    return np.where(r >= np.pi, r - 2 * np.pi, r).astype(np.float32)


@pytest.mark.parametrize("k", [1, -7, 1_000, 123_457, 9_549_297, -15_000_000])
def test_map_rigid_theta_plus_2pi_k_is_theta(k):
    """Validity (and distance, clearance, steer_to) at theta + 2 pi k is that at the wrapped
    angle; before the wrap a third of the states near theta ~ 6e7 were wrong."""
    env = nj.make_env("rigid/1")
    rng = np.random.default_rng(abs(k))
    n = 4000
    s = np.stack([rng.uniform(0, 10, n), rng.uniform(0, 10, n), rng.uniform(-np.pi, np.pi, n)],
                 1).astype(np.float32)
    big = s.copy()
    big[:, 2] = (s[:, 2].astype(np.float64) + 2 * np.pi * k).astype(np.float32)
    wrapped = big.copy()
    wrapped[:, 2] = _wrap64(big[:, 2])
    assert np.max(np.abs(wrapped[:, 2])) <= np.pi
    valid = np.asarray(env.is_valid(big, padding=0.0))
    assert valid.tolist() == np.asarray(env.is_valid(wrapped, padding=0.0)).tolist()
    assert 0.2 < valid.mean() < 0.95
    d = np.asarray(env.distance(big[:-1], big[1:]))
    np.testing.assert_allclose(d, np.asarray(env.distance(wrapped[:-1], wrapped[1:])), atol=2e-5)
    clear = jax.vmap(env.robot.clearance, in_axes=(0, None, None))
    np.testing.assert_allclose(np.asarray(clear(jnp.asarray(big), env.world, 0.0)),
                               np.asarray(clear(jnp.asarray(wrapped), env.world, 0.0)), atol=2e-5)
    m = 300
    assert (np.asarray(env.steer_to(big[:m], big[m:2 * m], padding=0.0)).tolist()
            == np.asarray(env.steer_to(wrapped[:m], wrapped[m:2 * m], padding=0.0)).tolist())


def test_map_rigid_theta_beyond_the_limit_is_invalid():
    """Float32 angles >= 1e8 are 8 rad apart and carry no heading: invalid, blocked, like NaN."""
    env = nj.make_env("rigid/0")
    good = env.sample_states(jax.random.key(0), 3, padding=0.0)
    bad = good.copy()
    bad[:, 2] = [1e8, -3e9, 1e30]
    assert not np.asarray(env.is_valid(bad)).any()
    assert not np.asarray(env.steer_to(good, bad)).any()
    assert not np.asarray(env.steer_to(bad, good)).any()
    assert np.asarray(env.is_valid(good, padding=0.0)).all()


def _write_map(path: Path, preset: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({**PRESETS[preset], "name": "map"}))
    return path


def test_map_slug_is_unique_to_the_content(tmp_path):
    a = _write_map(tmp_path / "a" / "map.json", "point/1")
    b = _write_map(tmp_path / "b" / "map.json", "point/2")
    a2 = _write_map(tmp_path / "copy" / "map.json", "point/1")
    sa, sb = env_slug(str(a)), env_slug(str(b))
    assert sa != sb and sa.startswith("map-") and sb.startswith("map-") and len(sa) == 12
    assert env_slug(str(a2)) == sa  # the same map under two paths: one folder
    assert env_slug(str(a), nj.make_env(str(a))) == sa
    # presets keep their readable slug; an env that is not the preset never takes its folder
    assert env_slug("point/0") == "point_0" == env_slug("point/0", nj.make_env("point/0"))
    assert env_slug("point/0", nj.make_env("point/1")).startswith("point_0-")
    assert list(resolve_envs([str(a), str(b), "point/0"])) == [str(a), str(b), "point/0"]
    before = _tree(tmp_path)
    for names, listed in [([str(a), str(a2)], [str(a), str(a2)]),
                          (["point/2", str(b)], ["point/2", str(b)]),
                          (["point/0", "point/3", "point/0"], ["point/0", "point/0"])]:
        with pytest.raises(EnvError, match="envs lists the same environment more than once") as e:
            resolve_envs(names)
        for name in listed:
            assert repr(name) in str(e.value)
    assert _tree(tmp_path) == before


def test_map_same_file_names_run_into_their_own_folders(tmp_path):
    """Silent failure 1: two different maps both named map.json share no folder; each is
    trained on its own data and scored with its own models."""
    from ntq_jax.experiment.pipeline import load_config, prepare_run, run_pipeline
    from ntq_jax.training import load_ensemble

    # two maps of point/2's shape (its walls, one of them moved in ``a``) and the tiny run's
    # settings: the compiled programs are the session's tiny run's (same shapes)
    a = _write_map(tmp_path / "maps" / "a" / "map.json", "point/2")
    spec = json.loads(a.read_text())
    spec["boxes"][0][0] = 6.0
    a.write_text(json.dumps(spec))
    b = _write_map(tmp_path / "maps" / "b" / "map.json", "point/2")
    cfg = load_config(None, TINY + [f"envs=[{a}, {b}]"])
    run = prepare_run(cfg, tmp_path / "run")
    run_pipeline(cfg, run, progress=False, figures=False, log=lambda s: None)
    sa, sb = env_slug(str(a)), env_slug(str(b))
    assert sa != sb
    assert sorted(p.name for p in (run / "data").iterdir()) == sorted([sa, sb])
    assert sorted(p.name for p in (run / "models").iterdir()) == sorted([sa, sb])
    for f, slug in ((a, sa), (b, sb)):
        saved = json.loads((run / "data" / slug / "env.json").read_text())
        assert nj.Env.from_json(saved).content_hash() == nj.make_env(str(f)).content_hash()
    qa = np.load(run / "data" / sa / "D0" / "inputs.npy")
    qb = np.load(run / "data" / sb / "D0" / "inputs.npy")
    assert qa.shape != qb.shape or not np.array_equal(qa, qb)
    pa = jax.tree_util.tree_leaves(load_ensemble(run / "models" / sa).params)
    pb = jax.tree_util.tree_leaves(load_ensemble(run / "models" / sb).params)
    assert any(not np.array_equal(x, y) for x, y in zip(pa, pb))
    rows = json.loads((run / "results.json").read_text())["rows"]
    assert {r["env"] for r in rows} == {str(a), str(b)}
    for r in rows:
        slug = sa if r["env"] == str(a) else sb
        assert r["env_slug"] == slug and r["paths_file"].startswith(f"paths/{slug}/")


def test_map_duplicate_envs_write_no_data(tmp_path):
    """Two config entries for one folder fail before any dataset or model is written."""
    from ntq_jax.experiment.pipeline import load_config, prepare_run, run_pipeline

    a = _write_map(tmp_path / "a" / "map.json", "point/1")
    a2 = _write_map(tmp_path / "b" / "map.json", "point/1")
    cfg = load_config(None, [f"envs=[{a}, {a2}]", "data.k_train=30"])
    # the run folder is refused before anything is written ...
    with pytest.raises(EnvError, match=r"the same environment more than once.*map-"):
        prepare_run(cfg, tmp_path / "run")
    assert not (tmp_path / "run").exists()
    # ... and the pipeline itself checks again (a folder prepared by other means)
    run = tmp_path / "run2"
    run.mkdir()
    with pytest.raises(EnvError, match=r"the same environment more than once.*map-"):
        run_pipeline(cfg, run, progress=False, figures=False, log=lambda s: None)
    assert not (run / "data").exists() and not (run / "models").exists()


def _files(folder: Path) -> set:
    return {p.relative_to(folder) for p in folder.rglob("*")}


# --- queries, planners, measure_gamma, plan ---

KEY = jax.random.key(0)


@pytest.fixture(scope="module")
def point_env():
    return nj.make_env("point/3")


@pytest.mark.parametrize("call, exc, message", [
    (lambda e: e.sample_queries(KEY, -3), ValueError, r"n must be an int >= 0, got -3"),
    (lambda e: e.sample_queries(KEY, 2.7), TypeError, r"n must be an int >= 0, got 2\.7"),
    (lambda e: e.sample_queries(KEY, True), TypeError, r"n must be an int .*bool"),
    (lambda e: e.sample_queries(KEY, 4, p_nt=float("nan")), ValueError, r"p_nt must be a number in \[0, 1\]"),
    (lambda e: e.sample_queries(KEY, 4, p_nt=1.5), ValueError, r"p_nt must be a number in \[0, 1\], got 1\.5"),
    (lambda e: e.sample_queries(KEY, 4, p_nt=True), TypeError, r"p_nt must be a number in \[0, 1\]"),
    (lambda e: e.sample_queries(KEY, 4, p_nt=1.0, n_max=0), ValueError, r"n_max must be an int >= 1, got 0"),
    (lambda e: e.sample_queries(KEY, 4, p_nt=1.0, n_max=2.5), TypeError, r"n_max must be an int >= 1"),
    (lambda e: e.sample_states(KEY, -1), ValueError, r"n must be an int >= 0, got -1"),
    (lambda e: e.gamma_nt(KEY, 2.7), TypeError, r"n must be an int >= 1, got 2\.7"),
    (lambda e: e.gamma_nt(KEY, 0), ValueError, r"n must be an int >= 1, got 0"),
    (lambda e: e.gamma_nt(KEY, 100, chunk=-8), ValueError, r"chunk must be an int >= 1, got -8"),
    (lambda e: e.gamma_nt(KEY, 100, chunk=0), ValueError, r"chunk must be an int >= 1, got 0"),
    (lambda e: e.gamma_nt(KEY, 100, chunk=4096.0), TypeError, r"chunk must be an int >= 1"),
    (lambda e: e.gamma_nt(KEY, 100, chunk=10**12), ValueError, r"chunk must be an int in \[1, "),
], ids=["sq-negative", "sq-float", "sq-bool", "p_nt-nan", "p_nt-1.5", "p_nt-bool", "n_max-0",
        "n_max-float", "states-negative", "gamma-float", "gamma-0", "chunk-negative", "chunk-0",
        "chunk-float", "chunk-huge"])
def test_api_query_arguments(point_env, call, exc, message):
    with pytest.raises(exc, match=message):
        call(point_env)


def test_api_query_arguments_accept_numpy_ints(point_env):
    est = point_env.gamma_nt(KEY, np.int64(50), chunk=np.int32(1024))
    assert est.queries == 50
    q, kind = point_env.sample_queries(KEY, np.int32(3), p_nt=np.float32(0.5), n_max=np.int64(5))
    assert q.shape == (3, 2, 2) and kind.shape == (3,)


@pytest.mark.parametrize("planner, options, exc, message", [
    ("astar", {"resolution": 50}, ValueError,
     r"astar: resolution 50 is too coarse: .* 0 x 0 cells .* at least 2 x 2; use a resolution <= 10"),
    ("astar", {"resolution": 15}, ValueError, r"too coarse: .* 1 x 1 cells"),
    ("astar", {"resolution": 1e-6}, ValueError, r"astar: resolution 1e-06 is too fine: .* at most 8191"),
    ("astar", {"resolution": 0}, ValueError, r"astar: resolution must be a finite number > 0, got 0"),
    ("astar", {"resolution": "0.1"}, TypeError, r"astar: resolution must be a finite number"),
    ("astar", {"resolutin": 0.2}, TypeError, r"astar: unknown option 'resolutin'; its options are .*resolution"),
    ("astar", {"chunk_size": 0}, ValueError, r"astar: chunk_size must be an int >= 1, got 0"),
    ("astar", {"open_capacity": 10**9}, ValueError, r"astar: open_capacity must be an int in \[1, "),
    ("astar", {"smooth": "no"}, TypeError, r"astar: smooth must be True or False"),
    ("astar", {"check": "exact"}, ValueError, r"astar: check must be one of 'discretized', 'certified'"),
    ("visgraph", {"eps": -1.0}, ValueError, r"visgraph: eps must be a finite number > 0"),
    ("visgraph", {"arc_step": 3.0}, ValueError, r"visgraph: arc_step must be .* <= 1\.5708"),
    ("visgraph", {"resolution": 0.1}, TypeError, r"visgraph: unknown option 'resolution'"),
    ("roadmap", {"milestones": 2.5}, TypeError, r"roadmap: milestones must be an int >= 2"),
    ("roadmap", {"grow_rounds": 9}, ValueError, r"roadmap: grow_rounds must be an int in \[0, 8\]"),
    ("bitstar", {"workers": -1}, ValueError, r"bitstar: workers must be an int >= 0, got -1"),
    ("bitstar", {"time_budget": 0}, ValueError, r"bitstar: time_budget must be a finite number > 0"),
    ("bitstar", {"chunk_size": 0}, ValueError, r"bitstar: chunk_size must be an int >= 1, got 0"),
    ("bitstar", {"stop_on_first": "yes"}, TypeError, r"bitstar: stop_on_first must be True or False"),
    ("nope", {}, ValueError, r"unknown planner 'nope'; available: astar, .*bitstar, roadmap, .*visgraph"),
    ("astar", {"seed": 1.5}, TypeError, r"seed must be an int >= 0"),
], ids=lambda v: v if isinstance(v, str) else None)
def test_api_plan_options(point_env, planner, options, exc, message):
    q, _ = point_env.sample_queries(KEY, 2)
    t0 = time.perf_counter()
    with pytest.raises(exc, match=message):
        nj.plan(point_env, q, planner, **options)
    assert time.perf_counter() - t0 < 30  # refused up front, not after building a grid or graph


@pytest.mark.parametrize("queries, message", [
    (np.zeros((2, 2, 3), np.float32), r"queries must have shape \(K, 2, 2\) for point/3, got \(2, 2, 3\)"),
    (np.zeros((2, 2), np.float32), r"queries must have shape \(K, 2, 2\)"),
    ("start to goal", r"queries must be a numeric \(K, 2, 2\) array"),
])
def test_api_plan_queries(point_env, queries, message):
    with pytest.raises((TypeError, ValueError), match=message):
        nj.plan(point_env, queries, "astar")


def test_api_plan_astar_smallest_grid_plans(point_env):
    """The boundary of the resolution check: a 2 x 2 grid is accepted and plans."""
    q, _ = point_env.sample_queries(KEY, 2)
    res = nj.plan(point_env, q, "astar", resolution=10)
    assert res.info["grid_shape"] == (2, 2) and res.status.shape == (2,)


def test_api_roadmap_beyond_memory_is_refused_before_any_work(point_env, monkeypatch):
    """issue 52, rough edge 2: ``milestones=10**12`` ran 455 s, then blamed "free space is
    too small"; now one ValueError naming the option, the bytes and the fix, before any
    roadmap is built, also when only the growth rounds' doublings would not fit."""
    import re

    from ntq_jax.planners import options
    from ntq_jax.planners import roadmap as R

    def built(*args, **kwargs):
        raise AssertionError("roadmap built")

    monkeypatch.setattr(R, "roadmap_for", built)  # the check must come before any roadmap
    q, _ = point_env.sample_queries(KEY, 2)
    with pytest.raises(ValueError) as err:  # this machine's own available memory
        nj.plan(point_env, q, "roadmap", milestones=10**12)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith("roadmap: milestones 1,000,000,000,000 would need"), msg
    assert re.search(r"at least [\d,]+ bytes .* of memory available; use milestones <= ", msg), msg
    # the default settings (2 growth rounds) pass with 1 GB: about 0.3 GB in 7-D with k 30
    options.roadmap_memory_option("roadmap", R.DEFAULT_MILESTONES, 7, 30, grow_rounds=2,
                                  available=10**9)

    m, k = 10**6, 10  # memory for exactly this roadmap's first round
    monkeypatch.setattr(options, "available_memory", lambda: options.roadmap_bytes(m, 2, k))
    with pytest.raises(AssertionError, match="roadmap built"):  # round 0 fits: work starts
        nj.plan(point_env, q, "roadmap", milestones=m, k=k, grow_rounds=0)
    with pytest.raises(ValueError, match=r"roadmap: milestones 1,000,000 .* after 1 growth round "
                                         r"\(2,000,000 states\).* or fewer grow_rounds$") as err:
        nj.plan(point_env, q, "roadmap", milestones=m, k=k, grow_rounds=1)
    most = int(re.search(r"use milestones <= ([\d,]+)", str(err.value))[1].replace(",", ""))
    assert m // 3 < most < m  # the advice fits, one more does not
    with pytest.raises(AssertionError, match="roadmap built"):
        nj.plan(point_env, q, "roadmap", milestones=most, k=k, grow_rounds=1)
    with pytest.raises(ValueError, match=f"milestones {most + 1:,} would need"):
        nj.plan(point_env, q, "roadmap", milestones=most + 1, k=k, grow_rounds=1)


BITSTAR_SCRIPT = """\
import jax
import ntq_jax as nj
from ntq_jax.planners import STATUS_NAMES

env = nj.make_env("point/1")
q, _ = env.sample_queries(jax.random.key(0), 2)
res = nj.plan(env, q, "bitstar", time_budget=0.1, workers=2, stop_on_first=True)
print("STATUS", [STATUS_NAMES[int(s)] for s in res.status])
"""


def test_api_bitstar_from_script_without_main_guard(tmp_path):
    """Workers no longer re-run a user's script that lacks ``if __name__ == "__main__":``."""
    pytest.importorskip("ompl")
    script = tmp_path / "user_script.py"
    script.write_text(BITSTAR_SCRIPT)
    proc = subprocess.run([sys.executable, str(script)],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path,
                          env=_env())
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "STATUS ['solved', 'solved']" in proc.stdout
    assert proc.stdout.count("STATUS") == 1  # the script ran once, in the parent only
    assert "bootstrapping phase" not in proc.stderr and "Traceback" not in proc.stderr
    assert "workers cannot start" not in proc.stderr
    assert _files(tmp_path) == {Path("user_script.py")}


def _env():
    import os
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + [p for p in [env.get("PYTHONPATH")] if p])
    env.setdefault("JAX_PLATFORMS", "cpu")
    return env


@pytest.mark.parametrize("argv, message", [
    (["--padding", "nan"], "argument --padding: must be a finite number >= 0, got 'nan'"),
    (["--padding", "-1"], "argument --padding: must be a finite number >= 0"),
    (["--queries", "1e20"], "argument --queries: must be at most 1e+15, got '1e20'"),
    (["--queries", "2.5"], "argument --queries: must be a whole number >= 1"),
    (["--chunk", "1e12"], "argument --chunk: must be at most"),
    (["--max-hours", "0"], "argument --max-hours: must be a number of hours > 0"),
    (["--seed=-1"], "argument --seed: must be in [0, 4294967295], got -1"),
    (["--seed", str(2**64)], "argument --seed: must be in [0, 4294967295]"),
])
def test_gamma_script_bad_arguments(tmp_path, capsys, argv, message):
    mg = _script("measure_gamma")
    out = tmp_path / "gamma.json"
    with pytest.raises(SystemExit) as e:
        mg.main(argv + ["--json", str(out), "--no-progress"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not out.exists()


def test_gamma_script_json_unwritable_is_checked_first(tmp_path, capsys):
    mg = _script("measure_gamma")
    (tmp_path / "a_file").write_text("x")
    before = _files(tmp_path)
    for target, message in [(tmp_path / "a_file" / "gamma.json", "is a file, not a folder"),
                            (tmp_path, "is a folder; give a file name")]:
        t0 = time.perf_counter()
        assert mg.main(["--queries", "1e12", "--max-hours", "inf", "--no-progress",
                        "--json", str(target)]) == 2
        captured = capsys.readouterr()
        lines = captured.err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: --json") and message in lines[0]
        assert captured.out == ""  # no estimate: nothing was measured
        assert time.perf_counter() - t0 < 30  # 1e12 queries would take hours
    assert _files(tmp_path) == before


def test_gamma_script_refuses_a_run_longer_than_max_hours(tmp_path, capsys):
    mg = _script("measure_gamma")
    out = tmp_path / "gamma.json"
    assert mg.main(["--queries", "1e15", "--no-progress", "--json", str(out)]) == 2
    captured = capsys.readouterr()
    errors = [line for line in captured.err.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "--max-hours 24" in errors[0] and " h left" in errors[0]
    assert captured.out == "" and not out.exists() and _files(tmp_path) == set()


def test_gamma_script_ctrl_c_prints_the_estimate_so_far(tmp_path):
    out = tmp_path / "gamma.json"
    # A shell without job control starts a background job (`nohup pytest &`) with SIGINT
    # ignored, and an ignored signal stays ignored in the child; a handled one is reset to
    # the default at exec, so the child's Python turns Ctrl-C into KeyboardInterrupt again
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        proc = subprocess.Popen([sys.executable, str(ROOT / "scripts" / "measure_gamma.py"),
                                 "--queries", "1e12", "--max-hours", "inf", "--no-progress",
                                 "--json", str(out)],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                env=_env())
    finally:
        signal.signal(signal.SIGINT, before)
    try:
        first = proc.stderr.readline()  # the time estimate: streaming has started
        assert "queries/s: about" in first
        time.sleep(0.5)
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 130
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr
    assert "interrupted after" in stdout and "of 1,000,000,000,000 queries" in stdout
    gamma = [line for line in stdout.splitlines() if line.startswith("gamma_nt = ")]
    assert len(gamma) == 1
    value = float(gamma[0].split()[2])
    lo, hi = (float(v) for v in gamma[0].split("[")[1].rstrip("]").split(","))
    assert lo <= value <= hi and hi - lo < 0.01  # point/0 gamma_nt ~0.31, >= 1e6 queries counted
    assert "not written (interrupted)" in stderr and not out.exists()


def test_gamma_interrupted_carries_the_partial_estimate(point_env):
    """gamma_nt's KeyboardInterrupt is a GammaInterrupted with the chunks counted so far."""
    from ntq_jax.queries import GammaInterrupted

    calls = []

    def progress(done):
        calls.append(done)
        if len(calls) == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt) as e:
        point_env.gamma_nt(KEY, 10**9, padding=0.0, chunk=4096, progress=progress)
    assert isinstance(e.value, GammaInterrupted)
    est = e.value.estimate
    assert est.queries == calls[-1] > 0 and 0 < est.non_trivial < est.queries
    assert est.ci95[0] <= est.gamma <= est.ci95[1] and est.candidates == 3 * 4096
    full = point_env.gamma_nt(KEY, est.queries, padding=0.0, chunk=4096)
    assert full.non_trivial == est.non_trivial  # the same stream: an exact prefix


@pytest.fixture()
def bare_run(tmp_path):
    """A run folder with a config and no models: enough for plan.py's checks before loading."""
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.yaml").write_text("envs: [point/2]\n")
    return run


def test_plan_script_png_unwritable_is_checked_first(bare_run, tmp_path, capsys):
    plan = _script("plan")
    (tmp_path / "a_file").write_text("x")
    before = _files(tmp_path)
    for png, message in [(tmp_path / "a_file" / "fig.png", "is a file, not a folder"),
                         (tmp_path, "is a folder; give a file name")]:
        assert plan.main(["--run", str(bare_run), "--model", "0", "--start", "1", "1",
                          "--goal", "2", "2", "--png", str(png), "--no-compile-cache"]) == 2
        captured = capsys.readouterr()
        lines = captured.err.strip().splitlines()
        # the --png error, not the missing models: the check comes before any loading
        assert len(lines) == 1 and lines[0].startswith("error: --png") and message in lines[0]
        assert captured.out == ""
    assert _files(tmp_path) == before


def test_plan_script_takes_pnet_names_and_checks_the_figure_format_first(bare_run, tmp_path,
                                                                          capsys):
    plan = _script("plan")
    assert plan._model("PNet_3") == plan._model("3") == 3
    assert plan.main(["--run", str(bare_run), "--model", "PNet_0", "--start", "1", "1",
                      "--goal", "2", "2", "--png", str(tmp_path / "p.xyz"),
                      "--no-compile-cache"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--png" in err[0] and ".png, .pdf" in err[0]
    with pytest.raises(SystemExit):
        plan.main(["--run", str(bare_run), "--model", "PNet_x", "--start", "1", "1",
                   "--goal", "2", "2"])
    assert "expected N or PNet_<N>" in capsys.readouterr().err


def test_plan_script_default_png_checked_after_the_states(bare_run, capsys):
    """With a writable default figure path the script goes on to the models (missing here)."""
    plan = _script("plan")
    assert plan.main(["--run", str(bare_run), "--model", "0", "--start", "1", "1",
                      "--goal", "2", "2", "--no-compile-cache"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error:") and "--png" not in err
    assert not (bare_run / "figures").exists()


def test_api_json_of_gamma_script_round_trip(tmp_path, capsys):
    """A writable --json is written after the work, with the estimate printed."""
    mg = _script("measure_gamma")
    out = tmp_path / "sub" / "gamma.json"
    assert mg.main(["--queries", "2000", "--no-progress", "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["queries"] == 2000 and 0 < data["gamma"] < 1
    assert f"gamma_nt = {data['gamma']:.6f}" in capsys.readouterr().out


@pytest.mark.parametrize("boxes, words", [
    ([], ["D3", "pruning removed every segment", "drop D3 from data.datasets"]),
    ([[5, 5, 6, 6]], ["valid"]),  # every state occupied: the sampler's one line
])
def test_an_empty_or_full_map_through_train_all_is_one_line(tmp_path, capsys, boxes, words):
    """No obstacles: D3 (pruned) is empty, said before any training; no free space: the
    sampler's FreeSpaceTooSmall, one line (both were tracebacks)."""
    f = tmp_path / "m.json"
    f.write_text(json.dumps({**_POINT_MAP, "boxes": boxes, "discs": []}))
    args = [a for s in TINY if not s.startswith("envs=") for a in ("--set", s)]
    code = _script("train_all").main(args + ["--set", f"envs=[{f}]", "--out",
                                             str(tmp_path / "run"), "--no-progress",
                                             "--no-figures"])
    assert code == 2
    err = capsys.readouterr().err
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    # one error line, last; before it at most the generator's RuntimeWarning (shown when
    # pytest does not capture warnings)
    line = lines[-1]
    assert line.startswith("error:") and "Traceback" not in err and len(lines) <= 3, err
    for w in words:
        assert w in line, (w, line)
    assert not (tmp_path / "run" / "models" / "m" / "ensemble").exists()


@pytest.mark.parametrize("bad", [[["1", "1"]], np.array([[True, False]]),
                                 np.array([[1 + 1j, 2]]), [[1, [2]]]],
                         ids=["strings", "bool", "complex", "ragged"])
def test_states_must_be_real_numbers(bad):
    """steer_to / is_valid / distance refuse non-real input (["1","1"] was True)."""
    env = nj.make_env("point/0")
    for call in (lambda: env.steer_to(bad, bad), lambda: env.is_valid(bad),
                 lambda: env.distance(bad, bad)):
        with pytest.raises(TypeError, match="real numbers"):
            call()
    assert bool(env.is_valid(np.array([[1, 1]], np.int64))[0])  # integers are numbers


@pytest.mark.parametrize("script,argv", [
    ("generate_data", ["--env", "point/0", "--no-progress", "--no-compile-cache", "--out", "{out}"]),
    ("learning_curve", ["--sizes", "5", "--no-progress", "--no-compile-cache", "--out", "{out}"]),
    ("reproduce", ["--report-only", "--results", "{out}"]),
    ("reproduce", ["--config", "configs/point.yaml", "--results", "{out}"]),
    ("reproduce", ["--config", "configs/point.yaml", "--runs", "{out}"]),
])
def test_scripts_refuse_an_unwritable_output_folder_first(tmp_path, capsys, script, argv):
    mod = _script(script)
    (tmp_path / "a_file").write_text("x")
    before = _files(tmp_path)
    targets = [(tmp_path / "a_file" / "sub", "is a file, not a folder"),
               (tmp_path / "a_file", "is a file, not a folder")]
    if Path("/proc").is_dir():  # a read-only file system: refused even for root
        targets.append((Path("/proc/ntq_jax_out"), "creating a file in /proc failed"))
    for target, message in targets:
        rc = mod.main([a.format(out=target) for a in argv])
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 2 and len(err) == 1, err
        assert err[0].startswith("error: --") and message in err[0] and "writable" in err[0]
    assert _files(tmp_path) == before


def test_grid_astar_on_a_one_cell_grid_map_names_the_map_not_the_resolution(tmp_path):
    from ntq_jax import make_env
    from ntq_jax.planners import plan

    (tmp_path / "one.pgm").write_text("P2\n1 1\n255\n255\n")
    (tmp_path / "one.yaml").write_text("image: one.pgm\nresolution: 1.0\norigin: [0, 0, 0]\n"
                                       "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    env = make_env(tmp_path / "one.yaml")
    q = np.array([[[0.2, 0.2], [0.8, 0.8]]], np.float32)
    for opts in ({}, {"resolution": 0.5}):  # the advice must not be one that fails again
        with pytest.raises(ValueError, match=r"1 x 1-cell grid.*resolution option does not apply"
                                             r".*roadmap or visgraph"):
            plan(env, q, "astar", padding=0.0, **opts)
    # the advice works (a small roadmap: the default one checks some 600,000 edges)
    assert plan(env, q, "roadmap", padding=0.0, milestones=500).lengths[0] >= 2


def test_a_full_disk_during_train_all_is_one_line_and_the_run_resumes(run_copy, capsys,
                                                                       monkeypatch):
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
