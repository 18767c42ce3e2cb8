"""The public Env API: presets, JSON round trip, bad input, and the paper's gamma_nt."""

import json
import math
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest

import ntq_jax as nj

ROOT = Path(__file__).resolve().parents[1]


def test_presets_build_with_the_papers_paddings():
    pads = {"point": 0.8, "rigid": 0.4, "nlink": 0.8}
    dims = {"point": 2, "rigid": 3}
    assert set(nj.PRESETS) == set(nj.PAPER_GAMMA)
    for name in nj.PRESETS:
        env = nj.make_env(name)
        family = name.split("/")[0]
        assert env.padding == pads[family]
        assert env.dim == dims.get(family, int(name.split("/")[1]))


def test_json_round_trip(tmp_path):
    for name in nj.PRESETS:
        env = nj.make_env(name)
        path = env.save_json(tmp_path / (name.replace("/", "_") + ".json"))
        again = nj.make_env(path)
        assert again.to_json() == env.to_json()
        assert again.robot == env.robot


def test_user_map_from_json_file(tmp_path):
    spec = {"name": "mine", "robot": {"kind": "point"}, "bounds": [[0, 10], [0, 5]],
            "boxes": [[5, 2.5, 1, 1]], "discs": [[2, 2, 0.5]], "padding": 0.1}
    f = tmp_path / "mine.json"
    f.write_text(json.dumps(spec))
    env = nj.make_env(str(f))
    ok = np.asarray(env.is_valid(np.array([[5, 2.5], [1, 4], [2, 2.55], [11, 1]], np.float32)))
    assert ok.tolist() == [False, True, False, False]


@pytest.mark.parametrize("spec, match", [
    ({"robot": {"kind": "point"}, "bounds": [[0, 1], [0, 1]], "boxez": []}, "unknown key"),
    ({"robot": {"kind": "car"}, "bounds": [[0, 1], [0, 1]]}, "kind 'car' is unknown"),
    ({"robot": {"kind": "point"}}, "missing required key 'bounds'"),
    ({"robot": {"kind": "point"}, "bounds": [[1, 0], [0, 1]]}, "bounds"),
    ({"robot": {"kind": "point"}, "bounds": [[0, 1], [0, 1]], "boxes": [[0, 0, -1, 1]]}, "half sizes"),
    ({"robot": {"kind": "point"}, "bounds": [[0, 1], [0, 1]], "padding": -1}, "padding"),
    ({"robot": {"kind": "rigid_body", "lenght": 1}, "bounds": [[0, 1], [0, 1]]}, "unknown parameter"),
    ({"robot": {"kind": "nlink", "link_lengths": [1, -2]}, "bounds": [[0, 1], [0, 1]]}, "link_lengths"),
])
def test_bad_maps_are_one_clear_error(spec, match):
    with pytest.raises(nj.EnvError, match=match):
        nj.Env.from_json(spec)


def test_bad_names_and_files(tmp_path):
    with pytest.raises(nj.EnvError, match="unknown environment 'point/9'.*point/0"):
        nj.make_env("point/9")
    with pytest.raises(nj.EnvError, match="does not exist"):
        nj.make_env(str(tmp_path / "none.json"))
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(nj.EnvError, match="not valid JSON"):
        nj.make_env(str(bad))


@pytest.mark.parametrize("name", ["point/0", "rigid/0", "nlink/4"])
def test_nan_and_inf_states_are_invalid_and_blocked(name):
    env = nj.make_env(name)
    good = env.sample_states(jax.random.key(0), 3, padding=0.0)
    bad = good.copy()
    bad[0, 0], bad[1, -1], bad[2, 1] = np.nan, np.inf, -np.inf
    assert not np.asarray(env.is_valid(bad)).any()
    assert not np.asarray(env.steer_to(good, bad)).any()
    assert not np.asarray(env.steer_to(bad, good)).any()


def test_shape_errors_name_the_expected_shape():
    env = nj.make_env("rigid/1")
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        env.is_valid(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="padding"):
        env.is_valid(np.zeros((4, 3)), padding=-0.5)


def test_padding_selects_the_geometry():
    env = nj.make_env("point/0")
    box = np.asarray(env.world.boxes)[0]
    near = np.array([[box[0] + box[2] + 0.5 * env.padding, box[1]]], np.float32)
    assert not bool(env.is_valid(near)[0])            # inside the data-generation padding
    assert bool(env.is_valid(near, padding=0.0)[0])   # free on the evaluation geometry


def test_sample_queries_kinds_and_validity():
    env = nj.make_env("point/2")
    q, kind = env.sample_queries(jax.random.key(3), 300, p_nt=0.5)
    assert q.shape == (300, 2, 2) and kind.dtype == np.int8
    assert np.asarray(env.is_valid(q[:, 0])).all() and np.asarray(env.is_valid(q[:, 1])).all()
    nt = kind == nj.NON_TRIVIAL
    assert not np.asarray(env.steer_to(q[nt, 0], q[nt, 1])).any()
    assert 0.35 < nt.mean() < 0.65


def test_free_space_too_small_is_a_clear_error():
    env = nj.Env.from_json({"robot": {"kind": "point"}, "bounds": [[0, 1], [0, 1]],
                            "boxes": [[0.5, 0.5, 0.6, 0.6]]})
    with pytest.raises(nj.FreeSpaceTooSmall, match="free space"):
        env.sample_states(jax.random.key(0), 5)


@pytest.mark.parametrize("name", sorted(nj.PAPER_GAMMA))
def test_preset_gamma_matches_the_paper(name):
    """Within +-0.03 of the paper (the 1e6-query figures are in BENCHMARKS.md)."""
    env = nj.make_env(name)
    n = 400_000 if env.robot.kind == "point" else 6_000
    est = env.gamma_nt(jax.random.key(11), n, padding=0.0)
    target = nj.PAPER_GAMMA[name]
    half = 1.96 * math.sqrt(target * (1 - target) / n)
    assert abs(est.gamma - target) <= 0.03 + half, (name, est.gamma, target)


def test_export_env_script(tmp_path):
    out = tmp_path / "p3.json"
    r = subprocess.run([sys.executable, str(ROOT / "scripts/export_env.py"), "point/3", "--out",
                        str(out)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert nj.make_env(str(out)).to_json() == nj.make_env("point/3").to_json()
    r = subprocess.run([sys.executable, str(ROOT / "scripts/export_env.py"), "point/7"],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "unknown environment" in r.stderr


def test_measure_gamma_script_json(tmp_path):
    out = tmp_path / "g.json"
    r = subprocess.run([sys.executable, str(ROOT / "scripts/measure_gamma.py"), "--env", "point/0",
                        "--queries", "2e5", "--seed", "3", "--json", str(out), "--no-progress"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    res = json.loads(out.read_text())
    assert set(res) >= {"env", "queries", "non_trivial", "gamma", "ci95", "seconds",
                        "queries_per_second"}
    assert res["queries"] == 200_000 and res["env"] == "point/0"
    assert res["ci95"][0] <= res["gamma"] <= res["ci95"][1]
    assert res["non_trivial"] == round(res["gamma"] * res["queries"])
    assert "gamma_nt =" in r.stdout
