"""Path records (scripts/record_paths.py, ntq_jax.data.records): never overwritten, never
mixed, never trusted unverified; a damaged record is one line naming the file."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import warnings

import numpy as np
import pytest
from script_loader import load_script

from ntq_jax import make_env
from ntq_jax.experiment import config

SETS = ["data.k_train=12", "data.gamma_queries=500", "data.gamma_eval=false"]
ARGS = [
    "--config",
    "configs/point_small.yaml",
    "--env",
    "point/2",
    "--planner",
    "astar",
    "--chunk",
    "5",
    "--no-progress",
] + [a for s in SETS for a in ("--set", s)]


def _record(out, *extra) -> int:
    return load_script("record_paths").main(ARGS + ["--out", str(out), *extra])


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """One small astar record of point/2 (both pools, 12 + 12 queries, chunks of 5)."""
    rec = tmp_path_factory.mktemp("rec") / "rec"
    assert _record(rec) == 0
    return rec


@pytest.fixture
def rec(recorded, tmp_path):
    out = tmp_path / "rec"
    shutil.copytree(recorded, out, ignore=shutil.ignore_patterns(".lock"))
    return out


def _files(folder):
    return {
        p.relative_to(folder).as_posix(): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file() and p.name != ".lock"
    }


def _one_error(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: "), err
    return err[0]


@pytest.mark.parametrize("chunk", ["0", "-3"])
def test_a_chunk_below_one_is_refused_before_any_work(chunk, tmp_path, capsys):
    assert _record(tmp_path / "r", "--chunk", chunk) == 2
    assert "--chunk" in _one_error(capsys) and not (tmp_path / "r").exists()


def test_a_record_refuses_other_arguments_and_another_planner(rec, capsys):
    """Another seed (or map, config, planner) would replace or mix every chunk: refused,
    naming the difference, the record untouched; its own arguments resume it (another
    worker count too), and --pools X is one line."""
    before = _files(rec)
    for extra, word in (
        (["--set", "seed=1"], "seed"),
        (["--planner", "roadmap"], "planner"),
        (["--set", "data.k_train=20"], "overrides"),
    ):
        argv = ARGS + ["--out", str(rec)] + extra
        assert load_script("record_paths").main(argv) == 2
        line = _one_error(capsys)
        assert word in line and str(rec) in line and "record_paths.py" in line, line
        assert _files(rec) == before
    assert _record(rec, "--pools", "X") == 2 and "--pools X" in _one_error(capsys)
    assert _record(rec, "--workers", "2") == 0
    assert {k: v for k, v in _files(rec).items() if k != "record.json"} == {
        k: v for k, v in before.items() if k != "record.json"
    }


def test_a_record_is_one_recorder_and_a_killed_ones_temporary_files_go(rec, capsys):
    stale = rec / "N" / ".plan_000000010_000000012.npz.tmp-99999"
    stale.write_bytes(b"partial")
    code = (
        "import fcntl, sys; f = open(sys.argv[1], 'a+'); fcntl.flock(f, fcntl.LOCK_EX); "
        "print('locked', flush=True); sys.stdin.read()"
    )
    holder = subprocess.Popen(
        [sys.executable, "-c", code, str(rec / ".lock")],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "locked"
        assert _record(rec) == 2
        assert "another recorder" in _one_error(capsys) and stale.exists()
    finally:
        holder.stdin.close()
        holder.wait()
    assert _record(rec) == 0 and not stale.exists()


def _truncate(f):
    f.write_bytes(f.read_bytes()[:100])


def _empty(f):
    f.write_bytes(b"")


def _wrong_dimension(f):
    z = dict(np.load(f))
    z["paths"] = np.concatenate([z["paths"], z["paths"][..., :1]], axis=-1)
    np.savez(f, **z)


@pytest.mark.parametrize("damage", [_truncate, _empty, _wrong_dimension])
def test_a_damaged_chunk_is_one_line_naming_it(damage, rec, capsys):
    f = rec / "N" / "plan_000000005_000000010.npz"
    damage(f)
    assert _record(rec) == 2
    line = _one_error(capsys)
    assert str(f) in line and "delete it" in line
    from ntq_jax.data import records

    with pytest.raises(records.RecordError, match="plan_000000005_000000010.npz.*paths_from"):
        _generate(rec, rec.parent / "data")


def test_a_corrupt_record_json_is_one_line_naming_it(rec, capsys):
    (rec / "record.json").write_text('{"env": "point/2", ')
    assert _record(rec) == 2
    assert str(rec / "record.json") in _one_error(capsys)
    gen = load_script("generate_data")
    cfg = rec.parent / "c.yaml"
    cfg.write_text(
        "envs: [point/2]\ndata:\n  k_train: 12\n  per_env: [{env: point/2, "
        f"paths_from: '{rec}'}}]\n"
    )
    assert (
        gen.main(
            [
                "--config",
                str(cfg),
                "--out",
                str(rec.parent / "d"),
                "--no-progress",
                "--no-figures",
                "--no-compile-cache",
            ]
        )
        == 2
    )
    assert str(rec / "record.json") in _one_error(capsys)


def _cfg(rec, *extra):
    return config.load(
        "configs/point_small.yaml",
        SETS + [f"data.per_env=[{{env: point/2, paths_from: '{rec}'}}]", *extra],
    )


def _generate(rec, out):
    from ntq_jax import data

    return data.generate_datasets(
        make_env("point/2"),
        config.data_options(_cfg(rec), "point/2"),
        out,
        env_name="point/2",
        progress=False,
        figure=False,
    )


def test_recorded_paths_are_verified_before_they_enter_the_datasets(rec):
    """A recorded SOLVED path through an obstacle is rejected (unsolved) as a planner's
    would be; every data path is free at the data padding."""
    env = make_env("point/2")
    f = rec / "N" / "plan_000000000_000000005.npz"
    z = dict(np.load(f))
    i = int(np.flatnonzero(z["status"] == 0)[0])
    centre = np.asarray(env.world.boxes)[0, :2]  # a waypoint in the middle of an obstacle
    n = int(z["lengths"][i])
    z["paths"] = np.concatenate([z["paths"], np.full_like(z["paths"][:, :1], np.nan)], axis=1)
    z["paths"][i, 1 : n + 1] = z["paths"][i, 0:n].copy()
    z["paths"][i, 1] = centre
    z["lengths"][i] = n + 1
    np.savez(f, **z)
    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        _generate(rec, rec.parent / "data")
    assert any("1 of them from" in str(w.message) for w in got), [str(w.message) for w in got]
    d2 = np.load(rec.parent / "data" / "point_2" / "D2" / "paths.npy")
    lens = np.load(rec.parent / "data" / "point_2" / "D2" / "path_lengths.npy")
    for p, n in zip(d2, lens):
        assert np.asarray(env.steer_to(p[: n - 1], p[1:n])).all()
    meta = json.loads((rec.parent / "data" / "point_2" / "D2" / "meta.json").read_text())
    assert meta["planner"]["paths_from"]["record"] == str(rec)
    assert meta["planner"]["paths_from"]["planner"] == "astar"


def test_a_changed_record_makes_the_datasets_again(rec):
    """The datasets' fingerprint holds the record's chunks, not only its path."""
    first = _generate(rec, rec.parent / "data")
    assert not first["skipped"]
    assert _generate(rec, rec.parent / "data")["skipped"]
    f = rec / "U" / "plan_000000000_000000005.npz"
    z = dict(np.load(f))
    z["status"][:] = 2  # every query of the chunk unsolved: another record
    z["lengths"][:] = 0
    np.savez(f, **z)
    again = _generate(rec, rec.parent / "data")
    assert not again["skipped"] and again["fingerprint"] != first["fingerprint"]
