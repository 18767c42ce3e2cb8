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
    r = subprocess.run([sys.executable, str(ROOT / "scripts/export_env.py"), "point/3", "--out",
                        str(out)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert nj.make_env(str(out)).to_json() == nj.make_env("point/3").to_json()
    r = script("export_env", "point/7")
    assert r.returncode == 2 and "unknown environment" in r.stderr


def test_measure_gamma_script_json(tmp_path, script):
    out = tmp_path / "g.json"
    r = script("measure_gamma", "--env", "point/0", "--queries", "2e5", "--seed", "3", "--json", out,
               "--no-progress")
    assert r.returncode == 0, r.stderr
    res = json.loads(out.read_text())
    assert set(res) >= {"env", "queries", "non_trivial", "gamma", "ci95", "seconds",
                        "queries_per_second"}
    assert res["queries"] == 200_000 and res["env"] == "point/0"
    assert res["ci95"][0] <= res["gamma"] <= res["ci95"][1]
    assert res["non_trivial"] == round(res["gamma"] * res["queries"])
    assert "gamma_nt =" in r.stdout


# ---------------------------------------------------------------------------
# NumPy input (read in place when large; see ntq_jax.robots.batch.split_host_rows)

# Dyadic boxes and coordinates on a 1/16 grid: every product and sum in the exact
# segment test is exact in float32, so the answers cannot depend on how the
# compiler rounds (fused multiply-adds) and must agree bit for bit across layouts.
_DYADIC = {"name": "dyadic", "robot": {"kind": "point"}, "bounds": [[0, 20], [0, 20]],
           "boxes": [[10, 4, 0.5, 4], [10, 15, 0.5, 5], [4, 10, 4, 0.25], [15, 10, 2.5, 0.75]],
           "discs": [], "padding": 0.5}


def _grid_pairs(n, seed, dim=2, lo=-1, hi=21):
    rng = np.random.default_rng(seed)
    a = rng.integers(lo * 16, hi * 16, (n, dim)) / 16.0
    b = rng.integers(lo * 16, hi * 16, (n, dim)) / 16.0
    return a.astype(np.float32), b.astype(np.float32)


def _unaligned(x, phase):
    """A C-contiguous copy of ``x`` whose data starts ``phase`` bytes past a 64-byte boundary."""
    buf = np.empty(x.nbytes + 128, np.uint8)
    off = -buf.ctypes.data % 64 + phase
    out = buf[off:off + x.nbytes].view(x.dtype).reshape(x.shape)
    out[...] = x
    return out


@pytest.mark.parametrize("min_rows", [64, None])
def test_numpy_input_matches_device_input(monkeypatch, min_rows):
    from ntq_jax.robots import batch
    if min_rows is not None:  # small arrays through the in-place path too
        monkeypatch.setattr(batch, "HOST_MIN_ROWS", min_rows)
    env = nj.Env.from_json(_DYADIC)
    n = 3 * batch.HOST_MIN_ROWS + 5
    a, b = _grid_pairs(n, seed=1)
    split = (batch.steer_to_batch_split, batch.is_valid_batch_split, batch.distance_batch_split)
    programs = [f._cache_size() for f in split]
    dev_a, dev_b = jax.device_put(a), jax.device_put(b)
    for padding in (0.0, None):
        want = np.asarray(env.steer_to(dev_a, dev_b, padding=padding))
        assert 0.05 < want.mean() < 0.95
        valid = np.asarray(env.is_valid(dev_a, padding=padding))
        dist = np.asarray(env.distance(dev_a, dev_b))
        wide = np.concatenate([a, b], axis=1)
        inputs = {
            "float32": (a, b),
            "float64": (a.astype(np.float64), b.astype(np.float64)),
            "strided rows": (np.repeat(a, 2, axis=0)[::2], np.repeat(b, 2, axis=0)[::2]),
            "column slice": (wide[:, :2], wide[:, 2:]),
            "fortran order": (np.asfortranarray(a), np.asfortranarray(b)),
            "lists": (a.tolist(), b.tolist()),
        }
        for pa in (0, 8, 16, 24, 32, 48, 56):  # every row phase, a and b in and out of step
            inputs[f"phase {pa}"] = (_unaligned(a, pa), _unaligned(b, (pa + 16) % 64))
        for name, (x, y) in inputs.items():
            before = [np.array(v, copy=True) for v in (x, y)]
            got = env.steer_to(x, y, padding=padding)
            assert isinstance(got, jax.Array) and got.dtype == bool and got.shape == (n,), name
            np.testing.assert_array_equal(np.asarray(got), want, err_msg=name)
            np.testing.assert_array_equal(np.asarray(env.is_valid(x, padding=padding)), valid,
                                          err_msg=name)
            np.testing.assert_array_equal(np.asarray(env.distance(x, y)), dist, err_msg=name)
            for v, w in zip((x, y), before):
                np.testing.assert_array_equal(np.asarray(v), w, err_msg=f"{name}: input modified")
    # every row phase (the split's k) runs one compiled program per padding and size
    assert [f._cache_size() - c for f, c in zip(split, programs)] == [2, 2, 1]


def test_numpy_input_may_be_modified_after_the_call():
    from ntq_jax.robots import batch
    env = nj.Env.from_json(_DYADIC)
    # the size of test_numpy_input_matches_device_input[None] (above the default
    # HOST_MIN_ROWS, so the in-place path as users meet it): its compiled split and
    # device programs answer here, and a larger array only widens the window a call
    # returning early would leave
    a, b = _grid_pairs(3 * batch.HOST_MIN_ROWS + 5, seed=2)
    assert batch.host_rows(a, 2) is a  # read in place
    want = np.asarray(env.steer_to(jax.device_put(a), jax.device_put(b)))
    got = env.steer_to(a, b)
    a[:] = -5.0  # out of bounds: every answer would become False
    np.testing.assert_array_equal(np.asarray(got), want)


def test_numpy_input_on_a_preset_and_the_rigid_body(monkeypatch):
    # Random (not dyadic) states: the host-split and device programs compute each row
    # with the same elementwise arithmetic, so they agree unless the compiler contracted
    # a multiply-add in one program and not the other AND a state lies within that
    # rounding of contact. Checked with XLA told 128- and 512-bit vectors and with
    # --xla_cpu_max_isa=AVX (no FMA), on point/2 and rigid/0; the dyadic tests above are the
    # layout-proof ones.
    #
    # The maps and paddings are those of test_sample_queries_kinds_and_validity (point/2) and
    # test_varying_batch_sizes_share_compiled_programs (rigid/0), each at its own padding: the
    # subject (host-split program == device program, row for row) does not depend on which
    # preset or padding, and so the sampling and device-side programs are shared, only the
    # split programs under test are compiled here. The device reference of is_valid is read
    # in pieces of at most CHECK_CHUNK rows (Env's shared chunk path for device input, the
    # program sample_states runs) rather than one 4096-row bucket.
    from ntq_jax.robots import batch
    monkeypatch.setattr(batch, "HOST_MIN_ROWS", 64)
    for name in ("point/2", "rigid/0"):
        env = nj.make_env(name)
        s = np.asarray(env.sample_states(jax.random.key(0), 2 * 3000), np.float32)
        a, b = _unaligned(s[:3000], 16), _unaligned(s[3000:], 48)
        want = np.asarray(env.steer_to(jax.device_put(a), jax.device_put(b)))
        assert 0.05 < want.mean() < 0.95, (name, want.mean())  # both answers are compared
        np.testing.assert_array_equal(np.asarray(env.steer_to(a, b)), want, err_msg=name)
        valid = np.concatenate([np.asarray(env.is_valid(jax.device_put(a[i:i + batch.CHECK_CHUNK])))
                                for i in range(0, len(a), batch.CHECK_CHUNK)])
        np.testing.assert_array_equal(np.asarray(env.is_valid(a)), valid, err_msg=name)


def test_numpy_input_shape_errors():
    env = nj.make_env("point/3")
    a = np.zeros((100_000, 2), np.float32)
    with pytest.raises(ValueError, match="same shape"):
        env.steer_to(a, a[1:])
    with pytest.raises(ValueError, match=r"shape \(N, 2\)"):
        env.steer_to(np.zeros((100_000, 3), np.float32), np.zeros((100_000, 3), np.float32))


def test_varying_batch_sizes_share_compiled_programs():
    """Env.steer_to and is_valid run batches of 65 rows up to one chunk through the shared
    chunk programs of steer_to_pairs / valid_states, distance pads to power-of-two buckets:
    sizes 65..2048 compile at most one program of each, and every answer equals the one the
    bucketed kernels give the whole batch."""
    from ntq_jax.robots import batch as B
    env = nj.make_env("rigid/0")
    s = np.asarray(env.sample_states(jax.random.key(7), 4200), np.float32)
    a, b = s[:2048], s[2100:4148]
    programs = (B._steer_masked, B.is_valid_batch, B.distance_batch, B._steer_to_batch)
    env.steer_to(a[:65], b[:65]), env.is_valid(a[:65]), env.distance(a[:65], b[:65])
    before = [f._cache_size() for f in programs]
    outs = {n: (np.asarray(env.steer_to(a[:n], b[:n])), np.asarray(env.is_valid(a[:n])),
                np.asarray(env.distance(a[:n], b[:n]))) for n in (77, 100, 128, 1000, 2048)}
    after = [f._cache_size() for f in programs]
    assert after[0] == before[0] and after[1] == before[1] and after[3] == before[3], (before, after)
    assert after[2] - before[2] <= 4  # 128, 1024, 2048 (77 and 100 share 128's bucket)
    # the steer_to reference in 64-row pieces: the bucket program of Env's small batches
    # (test_nan_and_inf_states_are_invalid_and_blocked[rigid/0] compiles it), independent
    # of the chunk program under test, like one 2048-row call and without its compilation
    ref = (np.concatenate([np.asarray(B.steer_to_batch(env.robot, env.world, a[i:i + 64],
                                                       b[i:i + 64], env.padding))
                           for i in range(0, len(a), 64)]),
           np.asarray(B.is_valid_batch(env.robot, env.world, a, env.padding)),
           np.asarray(B.distance_batch(env.robot, a, b)))
    assert ref[0].any() and not ref[0].all()
    for n, got in outs.items():
        for g, r in zip(got, ref):
            assert g.shape == (n,)
            np.testing.assert_array_equal(g, r[:n])
