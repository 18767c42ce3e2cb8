"""Atomic writes (ntq_jax.artifacts): complete file or the old one, never a partial one."""

import json

import numpy as np
import pytest

from ntq_jax import artifacts


def test_writes_round_trip_and_leave_no_temporaries(tmp_path):
    artifacts.write_json(tmp_path / "sub" / "a.json", {"x": [1, 2]})
    artifacts.save_npy(tmp_path / "b.npy", np.arange(5, dtype=np.int32))
    artifacts.save_npz(tmp_path / "c.npz", y=np.ones(3))
    assert json.loads((tmp_path / "sub" / "a.json").read_text()) == {"x": [1, 2]}
    assert np.load(tmp_path / "b.npy").tolist() == [0, 1, 2, 3, 4]
    with np.load(tmp_path / "c.npz") as z:
        assert z["y"].tolist() == [1.0, 1.0, 1.0]
    assert not list(tmp_path.rglob(".*.tmp-*"))
    assert len(artifacts.sha256(tmp_path / "b.npy")) == 64


def test_a_failed_write_keeps_the_old_file_and_no_temporary(tmp_path):
    f = tmp_path / "a.txt"
    artifacts.write_text(f, "old")

    def boom(fh):
        fh.write(b"partial")
        raise RuntimeError("interrupted")

    with pytest.raises(RuntimeError):
        artifacts.write_with(f, boom)
    assert f.read_text() == "old"
    assert not list(tmp_path.glob(".*.tmp-*"))


def test_clean_tmp_removes_leftovers_only(tmp_path):
    (tmp_path / ".x.npy.tmp-123").write_bytes(b"junk")
    (tmp_path / "x.npy").write_bytes(b"keep")
    artifacts.clean_tmp(tmp_path)
    assert [p.name for p in tmp_path.iterdir()] == ["x.npy"]


def test_write_folder_is_complete_or_absent(tmp_path):
    """A folder written with write_folder appears whole; a fill that fails leaves the old
    folder (or none) and a hidden temporary folder that clean_tmp removes."""
    from ntq_jax import artifacts

    def fill(d):
        (d / "a.txt").write_text("1")
        (d / "sub").mkdir()
        (d / "sub" / "b.txt").write_text("2")

    out = artifacts.write_folder(tmp_path / "ens", fill)
    assert (out / "sub" / "b.txt").read_text() == "2"

    def broken(d):
        (d / "a.txt").write_text("half")
        raise RuntimeError("interrupted")

    import pytest

    with pytest.raises(RuntimeError):
        artifacts.write_folder(tmp_path / "ens", broken)
    assert (tmp_path / "ens" / "a.txt").read_text() == "1"  # the complete folder is untouched
    leftovers = [p for p in tmp_path.iterdir() if p.name.startswith(".")]
    assert len(leftovers) == 1 and leftovers[0].is_dir()
    artifacts.clean_tmp(tmp_path)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
    artifacts.write_folder(tmp_path / "ens", fill)  # a rewrite replaces the old folder whole
    assert sorted(p.name for p in (tmp_path / "ens").iterdir()) == ["a.txt", "sub"]
