"""The public Env API: presets, JSON round trip, bad input, and the paper's gamma_nt."""

import json
import math
import subprocess
import sys
import warnings
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
    spec = {
        "name": "mine",
        "robot": {"kind": "point"},
        "bounds": [[0, 10], [0, 5]],
        "boxes": [[5, 2.5, 1, 1]],
        "discs": [[2, 2, 0.5]],
        "padding": 0.1,
    }
    f = tmp_path / "mine.json"
    f.write_text(json.dumps(spec))
    env = nj.make_env(str(f))
    ok = np.asarray(env.is_valid(np.array([[5, 2.5], [1, 4], [2, 2.55], [11, 1]], np.float32)))
    assert ok.tolist() == [False, True, False, False]


@pytest.mark.parametrize(
    "spec, match",
    [
        ({"robot": {"kind": "point"}, "bounds": [[0, 1], [0, 1]], "boxez": []}, "unknown key"),
        ({"robot": {"kind": "car"}, "bounds": [[0, 1], [0, 1]]}, "kind 'car' is unknown"),
        ({"robot": {"kind": "point"}}, "missing required key 'bounds'"),
        ({"robot": {"kind": "point"}, "bounds": [[1, 0], [0, 1]]}, "bounds"),
        (
            {"robot": {"kind": "point"}, "bounds": [[0, 1], [0, 1]], "boxes": [[0, 0, -1, 1]]},
            "half sizes",
        ),
        ({"robot": {"kind": "point"}, "bounds": [[0, 1], [0, 1]], "padding": -1}, "padding"),
        (
            {"robot": {"kind": "rigid_body", "lenght": 1}, "bounds": [[0, 1], [0, 1]]},
            "unknown parameter",
        ),
        (
            {"robot": {"kind": "nlink", "link_lengths": [1, -2]}, "bounds": [[0, 1], [0, 1]]},
            "link_lengths",
        ),
    ],
)
def test_bad_maps_are_one_clear_error(spec, match):
    with pytest.raises(nj.EnvError, match=match):
        nj.Env.from_json(spec)


@pytest.mark.parametrize(
    "bounds, boxes, match",
    [
        # beyond float32: was [0, inf] (a NumPy warning, then "no valid query" after 272 M draws)
        ([[0, 1e39], [0, 10]], [], r"bounds\[0\]\[1\] is 1e\+39, beyond float32's range"),
        # float32 spacing 8 at 1e8: the box would move by 2 (the bounds' top by 4)
        ([[1e8, 1e8 + 20], [0, 20]], [[1e8 + 10, 5, 1, 1]], r"bounds\[0\]\[1\] .* moved by 4"),
        ([[-1e6, 1e6], [0, 20]], [[1e6 - 10.3, 5, 1, 1]], None),  # 2 M wide: 0.03 moves pass
        ([[0, 20], [0, 20]], [[5.123456789, 5, 1, 1]], None),
    ],
)
def test_coordinates_float32_cannot_hold_are_refused(bounds, boxes, match):
    """The world keeps float32 coordinates: a JSON map whose numbers overflow float32, or
    move by more than validation.MAX_FLOAT32_MOVE of the map's size when rounded, is one
    EnvError naming the entry (a grid map's check is grid_maps.check_float32)."""
    spec = {"robot": {"kind": "point"}, "bounds": bounds, "boxes": boxes}
    if match is None:
        nj.Env.from_json(spec)
        return
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # refused before any overflow warning
        with pytest.raises(nj.EnvError, match=match):
            nj.Env.from_json(spec)
    three = {
        "robot": {"kind": "serial_arm", "preset": "panda"},
        "bounds": [bounds[0], bounds[1], [0, 20]],
        "spheres": [[b[0], b[1], 5, 1] for b in boxes],
    }
    with pytest.raises(nj.EnvError, match=match):
        nj.Env.from_json(three)


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
    # the good states only need to be valid: sampled at the map's own padding, as the other
    # tests of rigid/0 here sample (one compiled validity program for them all)
    good = env.sample_states(jax.random.key(0), 3)
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
    assert not bool(env.is_valid(near)[0])  # inside the data-generation padding
    assert bool(env.is_valid(near, padding=0.0)[0])  # free on the evaluation geometry


def test_sample_queries_kinds_and_validity():
    env = nj.make_env("point/2")
    q, kind = env.sample_queries(jax.random.key(3), 300, p_nt=0.5)
    assert q.shape == (300, 2, 2) and kind.dtype == np.int8
    assert np.asarray(env.is_valid(q[:, 0])).all() and np.asarray(env.is_valid(q[:, 1])).all()
    nt = kind == nj.NON_TRIVIAL
    assert not np.asarray(env.steer_to(q[nt, 0], q[nt, 1])).any()
    assert 0.35 < nt.mean() < 0.65


def test_free_space_too_small_is_a_clear_error():
    env = nj.Env.from_json(
        {"robot": {"kind": "point"}, "bounds": [[0, 1], [0, 1]], "boxes": [[0.5, 0.5, 0.6, 0.6]]}
    )
    with pytest.raises(nj.FreeSpaceTooSmall, match="free space"):
        env.sample_states(jax.random.key(0), 5)


@pytest.mark.parametrize("name", sorted(nj.PAPER_GAMMA))
def test_preset_gamma_matches_the_paper(name):
    """Within +-0.03 of the paper (the 1e6-query figures are in BENCHMARKS.md)."""
    env = nj.make_env(name)
    point = env.robot.kind == "point"
    n = 400_000 if point else 6_000
    # every preset reads its queries off the first rows of chunk 0 (the point robot's 400,000
    # from rows of 2**17 pairs of a 2**23 chunk, about two rows at its > 80% valid pairs; the
    # rigid body's and the arms' 6,000 from a 2**18 chunk): one compiled program per map
    # instead of two, and the same stream and counts as whole chunks of any size (the lanes of
    # chunk 0 do not depend on the chunk size: the point presets' estimates equal those of
    # the default 2**22 chunks exactly; test_queries.py::
    # test_gamma_nt_small_n_read_lane_by_lane_equals_whole_chunks checks the equality)
    est = env.gamma_nt(jax.random.key(11), n, padding=0.0, chunk=1 << 23 if point else 1 << 18)
    target = nj.PAPER_GAMMA[name]
    half = 1.96 * math.sqrt(target * (1 - target) / n)
    assert abs(est.gamma - target) <= 0.03 + half, (name, est.gamma, target)


def test_export_env_script(tmp_path, script):
    out = tmp_path / "p3.json"
    r = subprocess.run(
        [sys.executable, str(ROOT / "scripts/export_env.py"), "point/3", "--out", str(out)],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    assert nj.make_env(str(out)).to_json() == nj.make_env("point/3").to_json()
    r = script("export_env", "point/7")
    assert r.returncode == 2 and "unknown environment" in r.stderr


def test_measure_gamma_script_json(tmp_path, script):
    out = tmp_path / "g.json"
    r = script(
        "measure_gamma",
        "--env",
        "point/0",
        "--queries",
        "2e5",
        "--seed",
        "3",
        "--json",
        out,
        "--no-progress",
    )
    assert r.returncode == 0, r.stderr
    res = json.loads(out.read_text())
    assert set(res) >= {
        "env",
        "queries",
        "non_trivial",
        "gamma",
        "ci95",
        "seconds",
        "queries_per_second",
    }
    assert res["queries"] == 200_000 and res["env"] == "point/0"
    assert res["ci95"][0] <= res["gamma"] <= res["ci95"][1]
    assert res["non_trivial"] == round(res["gamma"] * res["queries"])
    assert "gamma_nt =" in r.stdout

    # --pool: units of one geometry with different seeds add up into one estimate
    other = dict(res, seed=4, queries=100_000, non_trivial=res["non_trivial"] // 3)
    (tmp_path / "g4.json").write_text(json.dumps(other))
    r = script("measure_gamma", "--pool", out, tmp_path / "g4.json", "--json", tmp_path / "p.json")
    assert r.returncode == 0, r.stderr
    pooled = json.loads((tmp_path / "p.json").read_text())
    blocked = res["non_trivial"] + other["non_trivial"]
    assert pooled["queries"] == 300_000 and pooled["non_trivial"] == blocked
    assert pooled["gamma"] == blocked / 300_000 and pooled["seeds"] == [3, 4]
    assert pooled["ci95"][0] < pooled["gamma"] < pooled["ci95"][1] and pooled["units"] == 2
    assert pooled["env"] == "point/0"
    # another world, with half the non-trivial queries
    half = dict(res, env="point/1", seed=5, non_trivial=res["non_trivial"] // 2)
    (tmp_path / "g1.json").write_text(json.dumps(half))
    argv = ["--pool", out, tmp_path / "g1.json", "--json", tmp_path / "p.json"]
    r = script("measure_gamma", *argv)
    pooled = json.loads((tmp_path / "p.json").read_text())
    assert r.returncode == 0 and pooled["env"] == ["point/0", "point/1"]
    # the family's mean (ntq_jax.world_mean): an unbounded family (t on the spread of the
    # two worlds, 1 df), then a family of 2 worlds, both measured (the queries alone)
    free = pooled["worlds"]
    assert free["measured"] == 2 and free["population"] is None and free["df"] == 1
    r = script("measure_gamma", *argv, "--population", "2")
    whole = json.loads((tmp_path / "p.json").read_text())["worlds"]
    mean = (res["gamma"] + half["non_trivial"] / 200_000) / 2
    assert r.returncode == 0 and whole["mean"] == pytest.approx(mean) and whole["df"] is None
    assert whole["ci95"][0] < mean < whole["ci95"][1] < mean + 0.01 < free["ci95"][1]
    assert "mean over 2 of 2 worlds" in r.stdout
    r = script("measure_gamma", *argv, "--population", "1")
    assert r.returncode == 2 and "smaller than the 2 envs" in r.stderr, r.stderr
    for bad, why in [
        (dict(other, seed=3), "same env and seed"),
        (dict(other, padding=0.5), "padding"),
    ]:
        (tmp_path / "bad.json").write_text(json.dumps(bad))
        r = script("measure_gamma", "--pool", out, tmp_path / "bad.json", "--json", tmp_path / "x")
        assert r.returncode == 2 and why in r.stderr and r.stderr.count("\n") == 1, r.stderr


# ---------------------------------------------------------------------------
# Any input, any size: pieces read in place and an edge (see ntq_jax.robots.rows)

# Dyadic boxes and coordinates on a 1/16 grid: every product and sum in the exact
# segment test is exact in float32, so the answers cannot depend on how the
# compiler rounds (fused multiply-adds) and must agree bit for bit across layouts.
_DYADIC = {
    "name": "dyadic",
    "robot": {"kind": "point"},
    "bounds": [[0, 20], [0, 20]],
    "boxes": [[10, 4, 0.5, 4], [10, 15, 0.5, 5], [4, 10, 4, 0.25], [15, 10, 2.5, 0.75]],
    "discs": [],
    "padding": 0.5,
}


def _grid_pairs(n, seed, dim=2, lo=-1, hi=21):
    rng = np.random.default_rng(seed)
    a = rng.integers(lo * 16, hi * 16, (n, dim)) / 16.0
    b = rng.integers(lo * 16, hi * 16, (n, dim)) / 16.0
    return a.astype(np.float32), b.astype(np.float32)


def _unaligned(x, phase):
    """A C-contiguous copy of ``x`` whose data starts ``phase`` bytes past a 64-byte boundary."""
    buf = np.empty(x.nbytes + 128, np.uint8)
    off = -buf.ctypes.data % 64 + phase
    out = buf[off : off + x.nbytes].view(x.dtype).reshape(x.shape)
    out[...] = x
    return out


@pytest.fixture
def small_pieces(monkeypatch):
    """Pieces of 64..256 rows, so that small batches take every route of the split."""
    from ntq_jax.robots import rows

    monkeypatch.setattr(rows, "PIECE_MIN", 64)
    monkeypatch.setattr(rows, "PIECE_MAX", 256)


@pytest.mark.parametrize("n", [37, 3 * 256 + 101])
def test_any_input_matches_the_kernel(small_pieces, n):
    """Every input kind and row phase, all edge (37 rows) and pieces with an overlapping last
    piece and an edge (869 rows): the answers of the bare kernels on the whole batch, and
    every phase shares the same few compiled programs."""
    from ntq_jax.robots import batch

    env = nj.Env.from_json(_DYADIC)
    a, b = _grid_pairs(n, seed=1)
    programs = [f._cache_size() for f in (batch._steer_masked, batch.is_valid_batch)]
    for padding in (0.0, 0.5):
        want = np.asarray(batch.steer_to_batch(env.robot, env.world, a, b, padding))
        assert 0.05 < want.mean() < 0.95
        valid = np.asarray(batch.is_valid_batch(env.robot, env.world, a, padding))
        dist = np.asarray(batch.distance_batch(env.robot, a, b))
        wide = np.concatenate([a, b], axis=1)
        inputs = {
            "device": (jax.device_put(a), jax.device_put(b)),
            "float32": (a, b),
            "float64": (a.astype(np.float64), b.astype(np.float64)),
            "int": (np.rint(a).astype(np.int32), np.rint(b).astype(np.int32)),
            "strided rows": (np.repeat(a, 2, axis=0)[::2], np.repeat(b, 2, axis=0)[::2]),
            "column slice": (wide[:, :2], wide[:, 2:]),
            "fortran order": (np.asfortranarray(a), np.asfortranarray(b)),
            "lists": (a.tolist(), b.tolist()),
        }
        for pa in (0, 8, 16, 24, 32, 48, 56):  # every row phase, a and b in and out of step
            inputs[f"phase {pa}"] = (_unaligned(a, pa), _unaligned(b, (pa + 16) % 64))
        for name, (x, y) in inputs.items():
            before = [np.array(v, copy=True) for v in (x, y)]
            if name == "int":
                xi, yi = (np.asarray(v, np.float32) for v in (x, y))
                want_i = np.asarray(batch.steer_to_batch(env.robot, env.world, xi, yi, padding))
                np.testing.assert_array_equal(
                    np.asarray(env.steer_to(x, y, padding=padding)), want_i
                )
                continue
            got = env.steer_to(x, y, padding=padding)
            assert isinstance(got, jax.Array) and got.dtype == bool and got.shape == (n,), name
            np.testing.assert_array_equal(np.asarray(got), want, err_msg=name)
            np.testing.assert_array_equal(
                np.asarray(env.is_valid(x, padding=padding)), valid, err_msg=name
            )
            np.testing.assert_array_equal(np.asarray(env.distance(x, y)), dist, err_msg=name)
            for v, w in zip((x, y), before):
                np.testing.assert_array_equal(np.asarray(v), w, err_msg=f"{name}: input modified")
    # pieces of 64..256 rows and one edge bucket per size: a handful of programs for every
    # input kind, phase and padding (two paddings, so at most twice the sizes)
    grown = [
        f._cache_size() - c for f, c in zip((batch._steer_masked, batch.is_valid_batch), programs)
    ]
    assert all(g <= 2 * 5 for g in grown), grown


def test_numpy_input_may_be_modified_after_the_call(small_pieces):
    from ntq_jax.robots import batch, rows

    env = nj.Env.from_json(_DYADIC)
    a, b = _grid_pairs(3 * 256 + 101, seed=2)
    a = _unaligned(a, 0)
    assert rows.host_rows(a) is a  # read in place
    want = np.asarray(batch.steer_to_batch(env.robot, env.world, a, b, env.padding))
    got = env.steer_to(a, b)
    a[:] = -5.0  # out of bounds: every answer would become False
    np.testing.assert_array_equal(np.asarray(got), want)


def test_numpy_input_on_a_preset_and_the_rigid_body(small_pieces):
    # Random (not dyadic) states through the pieces and the edge: each row is computed by
    # the same elementwise arithmetic in every program, so the answers agree with the
    # bare kernel on the whole batch.
    from ntq_jax.robots import batch

    for name in ("point/2", "rigid/0"):
        env = nj.make_env(name)
        s = np.asarray(env.sample_states(jax.random.key(0), 2 * 1000), np.float32)
        a, b = _unaligned(s[:1000], 16), _unaligned(s[1000:], 48)
        want = np.asarray(batch.steer_to_batch(env.robot, env.world, a, b, env.padding))
        assert 0.05 < want.mean() < 0.95, (name, want.mean())  # both answers are compared
        np.testing.assert_array_equal(np.asarray(env.steer_to(a, b)), want, err_msg=name)
        np.testing.assert_array_equal(np.asarray(env.steer_to(jax.device_put(a), b)), want)
        valid = np.asarray(batch.is_valid_batch(env.robot, env.world, a, env.padding))
        np.testing.assert_array_equal(np.asarray(env.is_valid(a)), valid, err_msg=name)


def test_numpy_input_shape_errors():
    env = nj.make_env("point/3")
    a = np.zeros((100_000, 2), np.float32)
    with pytest.raises(ValueError, match="same shape"):
        env.steer_to(a, a[1:])
    with pytest.raises(ValueError, match=r"shape \(N, 2\)"):
        env.steer_to(np.zeros((100_000, 3), np.float32), np.zeros((100_000, 3), np.float32))


def test_varying_batch_sizes_share_compiled_programs():
    """Env.steer_to, is_valid and distance pad small batches to one of four sizes per power
    of two (less than a quarter of padding): sizes 65..2048 compile at most one program per
    size class, and every answer equals the bare kernel's on the whole batch (two classes,
    80 and 1024 rows, so the test compiles little)."""
    from ntq_jax.batching import fine_bucket_size
    from ntq_jax.robots import batch as B

    env = nj.make_env("rigid/0")
    s = np.asarray(env.sample_states(jax.random.key(7), 4200), np.float32)
    a, b = s[:1024], s[2100:3124]
    programs = (B._steer_masked, B.is_valid_batch, B.distance_batch)
    sizes = (65, 77, 80, 1000, 1024)
    before = [f._cache_size() for f in programs]
    outs = {
        n: (
            np.asarray(env.steer_to(a[:n], b[:n])),
            np.asarray(env.is_valid(a[:n])),
            np.asarray(env.distance(a[:n], b[:n])),
        )
        for n in sizes
    }
    after = [f._cache_size() for f in programs]
    classes = len({fine_bucket_size(n, 64) for n in sizes})  # 80 and 1024
    assert all(x - y <= classes for x, y in zip(after, before)), (before, after)
    ref = (
        np.asarray(B.steer_to_batch(env.robot, env.world, a, b, env.padding)),
        np.asarray(B.is_valid_batch(env.robot, env.world, a, env.padding)),
        np.asarray(B.distance_batch(env.robot, a, b)),
    )
    assert ref[0].any() and not ref[0].all()
    for n, got in outs.items():
        for g, r in zip(got, ref):
            assert g.shape == (n,)
            np.testing.assert_array_equal(g, r[:n])


def test_measure_gamma_family_of_worlds(tmp_path, script, monkeypatch):
    """``--env panda/<scene>``: one unit per member, each with its own seed (its queries
    those of the single run of that env and seed), written beside --json and skipped when
    there, pooled after each with the family's mean; a unit file of another measurement is
    never overwritten. Three point maps stand in for a scene's problems (no compilation)."""
    from ntq_jax.experiment import gamma_units

    members = ["point/0", "point/1", "point/2"]
    monkeypatch.setattr(gamma_units, "family", lambda name: members if name == "fam" else None)
    pooled = tmp_path / "series" / "fam.json"
    base = ["--env", "fam", "--queries", "3e4", "--json", pooled, "--no-progress"]
    r = script("measure_gamma", *base, "--problems", "1,3")
    assert r.returncode == 0, r.stderr
    units = {p.name: json.loads(p.read_text()) for p in (tmp_path / "series" / "fam").iterdir()}
    assert sorted(units) == ["problem_0.json", "problem_2.json"]
    assert [units[k]["seed"] for k in sorted(units)] == [0, 2]  # member_seed(0, i, 3) = i
    single = tmp_path / "single.json"
    argv = ["--env", "point/2", "--seed", "2", "--queries", "1e4", "--json", single]
    assert script("measure_gamma", *argv, "--no-progress").returncode == 0
    assert json.loads(single.read_text())["non_trivial"] == units["problem_2.json"]["non_trivial"]
    part = json.loads(pooled.read_text())
    assert part["units"] == 2 and part["worlds"]["population"] == 3
    assert not part["worlds"]["shared_queries"] and part["worlds"]["df"] is not None

    r = script("measure_gamma", *base)  # resumes: only problem 2 is measured
    assert r.returncode == 0 and "of the 3 asked, 2 already in" in r.stdout, r.stdout
    whole = json.loads(pooled.read_text())
    assert whole["units"] == 3 and whole["worlds"]["df"] is None  # every world measured
    w = whole["worlds"]
    assert w["mean"] == pytest.approx(
        np.mean(
            [
                u["gamma"]
                for u in map(
                    json.loads,
                    (
                        (tmp_path / "series" / "fam" / f"problem_{i}.json").read_text()
                        for i in range(3)
                    ),
                )
            ]
        )
    )
    assert w["ci95"][1] - w["ci95"][0] < part["worlds"]["ci95"][1] - part["worlds"]["ci95"][0]

    r = script("measure_gamma", *base, "--seed", "1")  # another series, the same files
    assert r.returncode == 2 and "holds another measurement" in r.stderr, r.stderr
    assert json.loads((tmp_path / "series" / "fam" / "problem_0.json").read_text())["seed"] == 0


def test_gamma_units_family_seeds_and_shared_streams():
    """The family a scene name stands for, its members' seeds, and the pool's allowance
    for worlds measured on one query stream."""
    from ntq_jax.errors import UsageError
    from ntq_jax.experiment import gamma_units as G

    cage = G.family("panda/cage")
    assert len(cage) == 100 and cage[0] == "panda/cage/1" and cage[-1] == "panda/cage/100"
    assert G.family("panda/cage/1") is None and G.family("point/0") is None
    with pytest.raises(UsageError, match="unknown Panda scene"):
        G.family("panda/kitchen")
    assert G.unit_path("s/cage.json", "panda/cage/7") == Path("s/cage/problem_7.json")
    assert [G.member_seed(s, i, 100) for s, i in [(0, 0), (0, 99), (1, 0)]] == [0, 99, 100]
    assert G.member_seed(2**32 // 100 - 1, 99, 100) == 2**32 - 1 - 96
    with pytest.raises(UsageError, match="seed below 42949672"):
        G.member_seed(2**32 // 100, 99, 100)
    unit = dict(padding=0.0, chunk=4096, resolution=1 / 32, check="discretized", queries=1000)
    units = [dict(unit, env=f"w/{i}", seed=0, non_trivial=300 + 10 * i) for i in range(4)]
    shared = G.pool(units, population=4)
    alone = G.pool([dict(u, seed=i) for i, u in enumerate(units)], population=4)
    assert shared["worlds"]["shared_queries"] and not alone["worlds"]["shared_queries"]
    assert "too narrow" in shared["world"] and G.shared_streams(units) == [0]
    width = [p["worlds"]["ci95"][1] - p["worlds"]["ci95"][0] for p in (shared, alone)]
    assert width[0] > 1.9 * width[1]  # the query term at its bound, not divided by 4
    with pytest.raises(UsageError, match="smaller than the 4 envs"):
        G.pool(units, population=3)
