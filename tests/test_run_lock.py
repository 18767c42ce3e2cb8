"""One process per run folder: a second run on a folder in use stops at once, naming the holder."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from script_loader import load_script

from ntq_jax import artifacts

ROOT = Path(__file__).resolve().parents[1]
TINY = [
    "envs=[point/2]",
    "data.k_train=40",
    "data.gamma_queries=2000",
    "data.gamma_eval=false",
    "train.epochs=2",
    "model.hidden=[32,32]",
    "eval.k_test=16",
]


def _holder(run: Path, how: str) -> subprocess.Popen:
    """A process that takes ``run`` (``how``: 'prepare_run' or 'lock') and waits on stdin."""
    take = (
        f"from ntq_jax.experiment.pipeline import load_config, prepare_run\n"
        f"prepare_run(load_config(None, {TINY!r}), {str(run)!r})"
        if how == "prepare_run"
        else f"from ntq_jax import artifacts\nartifacts.lock_folder({str(run)!r})"
    )
    code = textwrap.dedent(take) + "\nprint('held', flush=True)\nimport sys; sys.stdin.read()\n"
    env = dict(os.environ, PYTHONPATH=str(ROOT), JAX_PLATFORMS="cpu")
    p = subprocess.Popen(
        [sys.executable, "-c", code],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env=env,
        cwd=ROOT,
    )
    assert p.stdout.readline().strip() == "held"
    return p


def _train_all():
    return load_script("train_all", "_lock_train_all")


def test_second_run_on_a_folder_in_use_is_one_line_naming_the_pid(tmp_path, capsys):
    run = tmp_path / "run"
    holder = _holder(run, "prepare_run")
    try:
        before = {p.name: p.stat().st_mtime_ns for p in run.iterdir()}
        assert before.keys() == {".lock", "run.json", "config.yaml"}
        sets = sum((["--set", s] for s in TINY), [])
        for extra in ([], ["--overwrite"], ["--set", "model.hidden=[16,16]", "--overwrite"]):
            rc = _train_all().main(sets + extra + ["--out", str(run), "--no-progress"])
            err = capsys.readouterr().err.strip().splitlines()
            assert rc == 2 and len(err) == 1 and err[0].startswith("error: "), err
            assert f"in use by pid {holder.pid}" in err[0] and "--out" in err[0], err[0]
            # neither adopted, overwritten nor touched
            assert {p.name: p.stat().st_mtime_ns for p in run.iterdir()} == before
    finally:
        holder.kill()
        holder.wait()
    # a killed holder leaves no stale lock: the folder is usable at once
    from ntq_jax.experiment.pipeline import load_config, prepare_run

    assert prepare_run(load_config(None, TINY), run) == run
    assert f"pid {os.getpid()} " in (run / ".lock").read_text()
    artifacts.unlock_folder(run)


def test_lock_folder_is_exclusive_between_processes_and_reentrant_within_one(tmp_path):
    holder = _holder(tmp_path, "lock")
    try:
        with pytest.raises(artifacts.FolderInUse, match=f"in use by pid {holder.pid} on "):
            artifacts.lock_folder(tmp_path)
        assert artifacts.lock_holder(tmp_path).startswith(f"pid {holder.pid} on ")  # read only
    finally:
        holder.stdin.close()  # the holder ends normally
        holder.wait()
    assert artifacts.lock_holder(tmp_path) is None
    assert artifacts.lock_folder(tmp_path) == tmp_path / ".lock"
    assert artifacts.lock_folder(tmp_path) == tmp_path / ".lock"  # already held: no error
    artifacts.unlock_folder(tmp_path)
    artifacts.unlock_folder(tmp_path)  # not held: no-op


def test_refused_folder_gets_no_lock_file(tmp_path):
    """An old run folder (no .lock) of another config is refused without a file added."""
    from ntq_jax.experiment.pipeline import PipelineError, load_config, prepare_run

    run = tmp_path / "run"
    prepare_run(load_config(None, TINY), run)
    artifacts.unlock_folder(run)
    (run / ".lock").unlink()
    before = sorted(p.name for p in run.iterdir())
    with pytest.raises(PipelineError, match="another config"):
        prepare_run(load_config(None, TINY + ["model.hidden=[16,16]"]), run)
    assert sorted(p.name for p in run.iterdir()) == before


def test_a_file_system_without_locks_is_one_line_saying_so(tmp_path, capsys, monkeypatch):
    """flock failing with ENOLCK (e.g. some network file systems) is not "in use by
    another process" forever: one line says locks are not supported and what to do."""
    import errno
    import fcntl

    def no_locks(fd, op):
        raise OSError(errno.ENOLCK, "No locks available")

    monkeypatch.setattr(fcntl, "flock", no_locks)
    sets = sum((["--set", s] for s in TINY), [])
    assert _train_all().main(sets + ["--out", str(tmp_path / "run"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "does not support file locks" in err[0], err
    assert "in use" not in err[0]
