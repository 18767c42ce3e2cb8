"""Hostile inputs, maps and environments: JSON map rows, resolution floors, rigid-body angles,
map slugs, empty and full maps, states that are not numbers.

Every expected failure is one clear error, nothing is written where it must not be
(split from tests/test_bad_inputs.py by the surface each test probes; the shared
helpers are in bad_inputs_common.py).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from bad_inputs_common import ROOT, TINY, _script

import ntq_jax as nj
from ntq_jax.envs import MAX_STATES_PER_MOTION, EnvError, env_slug, resolve_envs
from ntq_jax.presets import PRESETS


def _tree(path: Path) -> dict[str, bytes]:
    """Every file under ``path`` with its bytes (to assert that nothing was written or changed)."""
    return {
        str(p.relative_to(path)): p.read_bytes() for p in sorted(path.rglob("*")) if p.is_file()
    }


_POINT_MAP = {
    "name": "m",
    "robot": {"kind": "point"},
    "bounds": [[0, 10], [0, 10]],
    "boxes": [[5, 5, 1, 1]],
    "discs": [[2, 2, 0.5]],
    "padding": 0.1,
}


_ARM = {"kind": "nlink", "link_lengths": [2.0, 2.0], "base": [5.0, 5.0], "resolution": 0.02}


_RIGID = {
    "kind": "rigid_body",
    "length": 1.2,
    "width": 0.4,
    "angle_weight": 0.5,
    "resolution": 0.05,
}


@pytest.mark.parametrize(
    "patch, match",
    [
        # rows of the wrong width are refused, never reshaped into other geometry
        (
            {"discs": [[1, 2, 1, 1], [5, 5, 1, 1], [3, 3, 1, 1]]},
            r"discs\[0\] is \[1, 2, 1, 1\] \(4 numbers\): expected \[cx, cy, r\] \(3 numbers\)",
        ),
        (
            {"boxes": [[1, 2, 1, 1, 3, 3]]},
            r"boxes\[0\] is \[1, 2, 1, 1, 3, 3\] \(6 numbers\): expected \[cx, cy, half_w, half_h\]",
        ),
        (
            {"boxes": [5, 5, 1, 1]},
            r"boxes\[0\] is 5, not a row: expected a list of rows \[cx, cy, half_w, half_h\]",
        ),
        (
            {"boxes": [[5, 5, 1, 1], [1, 2, 3]]},
            r"boxes\[1\] is \[1, 2, 3\] \(3 numbers\): expected \[cx, cy, half_w, half_h\] \(4 numbers\)",
        ),
        ({"boxes": None}, r"boxes must be a list of rows \[cx, cy, half_w, half_h\].*got null"),
        (
            {"bounds": [[0, 10, 20], [0, 10]]},
            r"bounds\[0\] is \[0, 10, 20\].*expected \[min, max\]",
        ),
        ({"bounds": [0, 10, 0, 10]}, r"bounds\[0\] is 0, not a row"),
        # entries are numbers: not bools, not strings
        (
            {"boxes": [[5, "5", 1, 1]]},
            r"boxes\[0\] is \[5, '5', 1, 1\]: '5' is not a finite number",
        ),
        ({"discs": [[2, 2, True]]}, r"discs\[0\] is \[2, 2, True\]: True is not a finite number"),
        ({"padding": True}, r"padding must be a number >= 0, got True \(bool\)"),
        ({"padding": "0.5"}, r"padding must be a number >= 0, got '0.5' \(str\)"),
        ({"name": None}, r"name must be a non-empty string, got None"),
        (
            {"robot": {**_ARM, "link_lengths": "22"}},
            r"robot: nlink.link_lengths must be a list \[l1, l2, \.\.\.\].*got '22' \(str\)",
        ),
        (
            {"robot": {**_ARM, "base": "55"}},
            r"robot: nlink.base must be a list \[x, y\] \(2 numbers\), got '55' \(str\)",
        ),
        ({"robot": {**_ARM, "base": [1, 2, 3]}}, r"nlink.base is \[1, 2, 3\]: expected \[x, y\]"),
        ({"robot": {**_ARM, "link_lengths": [2, False]}}, r"nlink.link_lengths\[1\] is False"),
        (
            {"robot": {**_RIGID, "length": True}},
            r"rigid_body.length must be a number > 0, got True",
        ),
        ({"robot": {**_RIGID, "resolution": None}}, r"rigid_body.resolution must be a number > 0"),
        ({"robot": {"kind": ["point"]}}, r"robot.kind \['point'\] is unknown"),
        # bounded discretisation: no resolution that makes one motion check millions of states
        (
            {"robot": {**_RIGID, "resolution": 1e-9}},
            (
                r"rigid_body.resolution 1e-09 is too fine: the longest motion \(15.71\).*1.57e\+10 states; "
                r"use resolution >= 0.000157 \(at most 100000 states per motion\)"
            ),
        ),
        (
            {"robot": {**_ARM, "resolution": 1e-7}},
            r"nlink.resolution 1e-07 rad is too fine.*use resolution >= 8.89e-05 rad",
        ),
    ],
)
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
    env = nj.Env.from_json(
        {
            **_POINT_MAP,
            "boxes": [(5, 5, 1, 1), np.array([8, 8, 0.5, 0.5])],
            "discs": [],
            "padding": 0,
        }
    )
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
    env = nj.Env.from_json(
        {**_POINT_MAP, "boxes": [], "discs": [], "robot": {**_RIGID, "resolution": floor * 1.01}}
    )
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
    s = np.stack(
        [rng.uniform(0, 10, n), rng.uniform(0, 10, n), rng.uniform(-np.pi, np.pi, n)], 1
    ).astype(np.float32)
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
    np.testing.assert_allclose(
        np.asarray(clear(jnp.asarray(big), env.world, 0.0)),
        np.asarray(clear(jnp.asarray(wrapped), env.world, 0.0)),
        atol=2e-5,
    )
    m = 300
    assert (
        np.asarray(env.steer_to(big[:m], big[m : 2 * m], padding=0.0)).tolist()
        == np.asarray(env.steer_to(wrapped[:m], wrapped[m : 2 * m], padding=0.0)).tolist()
    )


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
    for names, listed in [
        ([str(a), str(a2)], [str(a), str(a2)]),
        (["point/2", str(b)], ["point/2", str(b)]),
        (["point/0", "point/3", "point/0"], ["point/0", "point/0"]),
    ]:
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


@pytest.mark.parametrize(
    "boxes, words",
    [
        ([], ["D3", "pruning removed every segment", "drop D3 from data.datasets"]),
        ([[5, 5, 6, 6]], ["valid"]),  # every state occupied: the sampler's one line
    ],
)
def test_an_empty_or_full_map_through_train_all_is_one_line(tmp_path, capsys, boxes, words):
    """No obstacles: D3 (pruned) is empty, said before any training; no free space: the
    sampler's FreeSpaceTooSmall, one line (both were tracebacks)."""
    f = tmp_path / "m.json"
    f.write_text(json.dumps({**_POINT_MAP, "boxes": boxes, "discs": []}))
    args = [a for s in TINY if not s.startswith("envs=") for a in ("--set", s)]
    code = _script("train_all").main(
        args
        + ["--set", f"envs=[{f}]", "--out", str(tmp_path / "run"), "--no-progress", "--no-figures"]
    )
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


@pytest.mark.parametrize(
    "bad",
    [[["1", "1"]], np.array([[True, False]]), np.array([[1 + 1j, 2]]), [[1, [2]]]],
    ids=["strings", "bool", "complex", "ragged"],
)
def test_states_must_be_real_numbers(bad):
    """steer_to / is_valid / distance refuse non-real input (["1","1"] was True)."""
    env = nj.make_env("point/0")
    for call in (
        lambda: env.steer_to(bad, bad),
        lambda: env.is_valid(bad),
        lambda: env.distance(bad, bad),
    ):
        with pytest.raises(TypeError, match="real numbers"):
            call()
    assert bool(env.is_valid(np.array([[1, 1]], np.int64))[0])  # integers are numbers
