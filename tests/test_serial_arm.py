"""The URDF serial arm (:mod:`ntq_jax.robots.serial_arm`, :mod:`ntq_jax.robots.urdf`).

What is checked, against what:

* Panda forward kinematics against Franka's published modified-DH parameters (Craig's
  convention, flange ``d = 0.107``, hand turned by ``-pi/4``), hand-coded in NumPy
  float64 here: every link frame and the hand frame on random joint vectors, 1e-5.
* The tiny test arm (``tests/data/tiny_arm.urdf``: revolute, revolute with a tilted
  origin, prismatic, continuous about a non-coordinate axis, a fixed tool, a mesh-only
  link) against a second kinematics written here from the same hard-coded numbers with
  scipy rotations, and against values worked out by hand.
* ``is_valid`` against a brute-force NumPy oracle (float64 distances to spheres and
  to oriented boxes, every checked sphere pair, joint limits) on random states, some
  outside the limits; states within 1e-4 of a decision boundary are not compared.
* Self-collision: a Panda folded onto its base is invalid (the hand hits links 1-2),
  the SRDF's "ready" pose is valid in an empty world.
* The certified check's sweep bounds are sound: over 200 states of random motions no
  sphere centre moves farther from its start, and no checked pair's distance changes
  more, than ``part_sweep_bounds``; ``part_clearances`` are all > 0 iff the state is
  valid; the certified check never frees a motion a dense oracle finds blocked.
* The parser's refusals: one line each, naming the file and the fix.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from ntq_jax import prng
from ntq_jax.geometry import World3D
from ntq_jax.robots import SerialArm
from ntq_jax.robots.urdf import read_arm

DATA = Path(__file__).parent / "data"
TINY_URDF = DATA / "tiny_arm.urdf"
TINY_SRDF = DATA / "tiny_arm.srdf"
HOME = np.array([0, -0.785, 0, -2.356, 0, 1.571, 0.785], np.float32)
FOLDED = np.array([0, 1.0, 0, -3.0, 0, 0.5, 0.785], np.float32)  # hand down onto the base
BOUNDS = [[-1, 1], [-1, 1], [-0.2, 1.5]]
EMPTY = World3D.create(BOUNDS)


def _cuboid(center, half, rotvec):
    r = Rotation.from_rotvec(rotvec).as_matrix()
    return list(center) + list(half) + list(r.ravel())


# ---------------------------------------------------------------------------
# Shared arms, worlds and compiled programs (module level: each compiles once)
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def panda():
    return SerialArm.panda()


@pytest.fixture(scope="module")
def tiny():
    return SerialArm.from_urdf(TINY_URDF, TINY_SRDF)


@pytest.fixture(scope="module")
def programs():
    """Jitted, vmapped kernels keyed by arm (static) so both tests of an arm share them."""
    return {
        "fk": jax.jit(lambda arm, q: jax.vmap(arm.forward_kinematics)(q), static_argnums=0),
        "tip": jax.jit(lambda arm, q: jax.vmap(arm.tip_pose)(q), static_argnums=0),
        "centers": jax.jit(lambda arm, q: jax.vmap(arm.sphere_centers)(q), static_argnums=0),
        "valid": jax.jit(
            lambda arm, q, w, p: jax.vmap(arm.is_valid, in_axes=(0, None, None))(q, w, p),
            static_argnums=(0, 3),
        ),
        "parts": jax.jit(
            lambda arm, q, w, p: jax.vmap(arm.part_clearances, in_axes=(0, None, None))(q, w, p),
            static_argnums=(0, 3),
        ),
        "sweep": jax.jit(lambda arm, a, b: jax.vmap(arm.part_sweep_bounds)(a, b), static_argnums=0),
    }


def _uniform(arm, rng, n, widen=0.0):
    lo, hi = np.asarray(arm.lower), np.asarray(arm.upper)
    pad = widen * (hi - lo)
    return rng.uniform(lo - pad, hi + pad, (n, arm.dim)).astype(np.float32)


# ---------------------------------------------------------------------------
# Panda: model and forward kinematics against modified DH
# ---------------------------------------------------------------------------

# Franka's modified DH (Craig): a_{i-1}, d_i, alpha_{i-1} for joints 1..7 and the flange
DH_A = [0.0, 0.0, 0.0, 0.0825, -0.0825, 0.0, 0.088, 0.0]
DH_D = [0.333, 0.0, 0.316, 0.0, 0.384, 0.0, 0.0, 0.107]
DH_ALPHA = [
    0.0,
    -math.pi / 2,
    math.pi / 2,
    math.pi / 2,
    -math.pi / 2,
    math.pi / 2,
    math.pi / 2,
    0.0,
]


def _dh_frames(q):
    """Frames of links 0..7, the flange and the hand (flange turned by -pi/4 about z)."""
    t = np.eye(4)
    out = [t]
    for i, theta in enumerate(list(q) + [0.0]):
        ca, sa = math.cos(DH_ALPHA[i]), math.sin(DH_ALPHA[i])
        ct, st = math.cos(theta), math.sin(theta)
        t = t @ np.array(
            [
                [ct, -st, 0, DH_A[i]],
                [st * ca, ct * ca, -sa, -DH_D[i] * sa],
                [st * sa, ct * sa, ca, DH_D[i] * ca],
                [0, 0, 0, 1],
            ]
        )
        out.append(t)
    hand = np.eye(4)
    hand[:3, :3] = Rotation.from_euler("z", -math.pi / 4).as_matrix()
    return out, out[-1] @ hand


def test_panda_model(panda):
    assert panda.joint_names == tuple(f"panda_joint{i}" for i in range(1, 8))
    assert panda.lower == (-2.9671, -1.8326, -2.9671, -3.1416, -2.9671, -0.0873, -2.9671)
    assert panda.upper == (2.9671, 1.8326, 2.9671, 0.0873, 2.9671, 3.8223, 2.9671)
    assert panda.num_spheres == 59 and panda.dim == 7 and panda.kind == "serial_arm"
    links = set(panda.sphere_links)
    assert {"panda_hand", "panda_leftfinger", "panda_rightfinger"} <= links
    assert panda.periodic == (False,) * 7 and panda.metric_weights == (1.0,) * 7
    assert panda.resolution == 1 / 32
    assert math.isclose(
        panda.longest_motion(EMPTY), math.dist(panda.lower, panda.upper), rel_tol=1e-12
    )
    lo, hi = panda.config_bounds(EMPTY)
    assert lo.dtype == jnp.float32 and np.allclose(hi, panda.upper)
    assert panda.to_json() == {"kind": "serial_arm", "preset": "panda", "resolution": 1 / 32}
    assert hash(panda) == hash(SerialArm.panda()) and panda == SerialArm.panda()
    # the SRDF pairs and the adjacent / same-body links are never checked
    checked = {(panda.sphere_links[i], panda.sphere_links[k]) for i, k in panda.self_pairs}
    assert ("panda_link5", "panda_hand") in checked
    assert (
        not {
            ("panda_link6", "panda_hand"),
            ("panda_link3", "panda_link5"),
            ("panda_link7", "panda_hand"),
            ("panda_link0", "panda_link1"),
        }
        & checked
    )


def test_panda_fk_matches_modified_dh(panda, programs):
    q = _uniform(panda, np.random.default_rng(0), 32)
    frames = np.asarray(programs["fk"](panda, q))
    tips = np.asarray(programs["tip"](panda, q))
    assert frames.shape == (32, 8, 4, 4)
    for k in range(len(q)):
        dh, hand = _dh_frames(q[k].astype(np.float64))
        np.testing.assert_allclose(frames[k], np.stack(dh[:8]), atol=1e-5)
        np.testing.assert_allclose(tips[k], hand, atol=1e-5)


def test_panda_self_collision(panda, programs):
    ok = np.asarray(programs["valid"](panda, np.stack([HOME, FOLDED]), EMPTY, 0.0))
    assert ok.tolist() == [True, False]
    parts = np.asarray(programs["parts"](panda, np.stack([HOME, FOLDED]), EMPTY, 0.0))
    s = panda.num_spheres
    assert np.all(parts[0] > 0)
    assert np.all(parts[1, :s] > 0)  # no obstacle: only pairs collide, the hand with links 1-2
    hit = {
        (panda.sphere_links[panda.self_pairs[p][0]], panda.sphere_links[panda.self_pairs[p][1]])
        for p in np.flatnonzero(parts[1, s:] <= 0)
    }
    assert {("panda_link1", "panda_hand"), ("panda_link2", "panda_hand")} <= hit


# ---------------------------------------------------------------------------
# The tiny arm: independent kinematics and a brute-force validity oracle
# ---------------------------------------------------------------------------

# (origin xyz, origin rpy, axis, type) of j1..j4, as in tests/data/tiny_arm.urdf
TINY_JOINTS = [
    ((0, 0, 0.1), (0, 0, 0), (0, 0, 1), "revolute"),
    ((0, 0, 0.15), (0.2, 0, 0), (0, 1, 0), "revolute"),
    ((0.25, 0, 0), (0, 0, 0), (1, 0, 0), "prismatic"),
    ((0.1, 0, 0), (0, 0, 0.5), (1, 1, 0), "continuous"),
]
TINY_TOOL = ((0.05, 0, 0), (0, math.pi / 2, 0))  # fixed wrist -> tool
# (link, frame, centre in the link frame, radius); the tool's link frame is TINY_TOOL
TINY_SPHERES = [
    ("base", 0, (0, 0, 0.03), 0.06),
    ("link1", 1, (0, 0, 0.08), 0.04),
    ("link2", 2, (0.1, 0, 0), 0.04),
    ("link2", 2, (0.2, 0, 0), 0.035),
    ("link3", 3, (0.05, 0, 0), 0.03),
    ("tool", 4, (0, 0.04, 0), 0.025),
    ("tool", 4, (0, -0.04, 0.02), 0.025),
]
# link pairs checked for self-collision: not adjacent, not in the SRDF, not one body
TINY_CHECKED = {
    ("base", "link3"),
    ("base", "tool"),
    ("link1", "tool"),
    ("link2", "tool"),
    ("link3", "tool"),
}
TINY_LIMITS = [(-2.5, 2.5), (-2.2, 2.2), (0.0, 0.15), (-math.pi, math.pi)]


def _tf(xyz, rpy):
    t = np.eye(4)
    t[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()  # Rz(yaw) Ry(pitch) Rx(roll)
    t[:3, 3] = xyz
    return t


def _tiny_frames(q):
    """Frames 0..4 of the tiny arm at ``q`` ``(N, 4)``, each ``(N, 4, 4)`` float64."""
    q = np.asarray(q, np.float64).reshape(-1, 4)
    frames = [np.broadcast_to(np.eye(4), (len(q), 4, 4))]
    for (xyz, rpy, axis, kind), qk in zip(TINY_JOINTS, q.T):
        motion = np.tile(np.eye(4), (len(q), 1, 1))
        u = np.asarray(axis, float) / np.linalg.norm(axis)
        if kind == "prismatic":
            motion[:, :3, 3] = qk[:, None] * u
        else:
            motion[:, :3, :3] = Rotation.from_rotvec(qk[:, None] * u).as_matrix()
        frames.append(frames[-1] @ _tf(xyz, rpy) @ motion)
    return frames


def _tiny_centers(q):
    """``(N, 7, 3)`` float64 sphere centres of the tiny arm at ``q`` ``(N, 4)``."""
    frames = _tiny_frames(q)
    out = []
    for link, f, c, _ in TINY_SPHERES:
        t = frames[f] @ _tf(*TINY_TOOL) if link == "tool" else frames[f]
        out.append((t @ np.append(c, 1.0))[:, :3])
    return np.stack(out, axis=1)


def _pairs(links, checked):
    """Sphere index pairs ``(i, k)``, ``i < k``, of the link pairs ``checked`` (either order)."""
    return [
        (i, k)
        for i in range(len(links))
        for k in range(i + 1, len(links))
        if (links[i], links[k]) in checked or (links[k], links[i]) in checked
    ]


TINY_PAIRS = _pairs([s[0] for s in TINY_SPHERES], TINY_CHECKED)


def _oracle_margin(centers, radii, pairs, world, padding):
    """``(N,)`` float64: the smallest of every sphere's obstacle clearance (minus ``padding``)
    and every pair's gap, for centres ``(N, S, 3)``."""
    c = np.asarray(centers, np.float64)
    r = np.asarray(radii, np.float64)
    m = np.full(c.shape[0], np.inf)
    for s in np.asarray(world.spheres, np.float64):
        d = np.linalg.norm(c - s[:3], axis=-1) - s[3]
        m = np.minimum(m, (d - r - padding).min(axis=1))
    for b in np.asarray(world.cuboids, np.float64):
        rot = b[6:].reshape(3, 3)
        q = np.abs((c - b[:3]) @ rot) - b[3:6]  # box coordinates R^T (p - c)
        d = np.linalg.norm(np.maximum(q, 0), axis=-1) + np.minimum(q.max(axis=-1), 0)
        m = np.minimum(m, (d - r - padding).min(axis=1))
    if pairs:
        i, k = np.asarray(pairs).T
        gap = np.linalg.norm(c[:, i] - c[:, k], axis=-1) - r[i] - r[k]
        m = np.minimum(m, gap.min(axis=1))
    return m


def _within(arm, q):
    lo, hi = np.asarray(arm.lower, np.float32), np.asarray(arm.upper, np.float32)
    return np.all((q >= lo) & (q <= hi), axis=1)


@pytest.fixture(scope="module")
def tiny_world():
    return World3D.create(
        BOUNDS,
        spheres=[[0.3, 0.2, 0.3, 0.08], [-0.2, 0.3, 0.4, 0.1], [0.1, -0.35, 0.2, 0.06]],
        cuboids=[
            _cuboid((0.35, -0.1, 0.5), (0.1, 0.05, 0.08), (0.3, 0.5, 0.1)),
            _cuboid((0, 0, -0.1), (1, 1, 0.02), (0, 0, 0)),
            _cuboid((-0.3, -0.2, 0.15), (0.05, 0.2, 0.1), (0, 0, 0.7)),
        ],
    )


def test_tiny_model(tiny):
    assert tiny.joint_names == ("j1", "j2", "j3", "j4")
    assert tiny.joint_types == ("revolute", "revolute", "prismatic", "continuous")
    assert tiny.sphere_links == tuple(s[0] for s in TINY_SPHERES)  # the mesh-only wrist: none
    assert tiny.sphere_radii == tuple(s[3] for s in TINY_SPHERES)
    np.testing.assert_allclose(np.stack([tiny.lower, tiny.upper], 1), TINY_LIMITS)
    checked = {(tiny.sphere_links[i], tiny.sphere_links[k]) for i, k in tiny.self_pairs}
    assert checked == TINY_CHECKED and set(tiny.self_pairs) == set(TINY_PAIRS)
    # the default tip is the last movable joint's child; the tool beyond it keeps its spheres
    as_tool = SerialArm.from_urdf(TINY_URDF, TINY_SRDF, tip="tool")
    assert (
        dataclasses.replace(as_tool, tip_transform=tiny.tip_transform, source=tiny.source) == tiny
    )
    assert tiny.to_json() == {
        "kind": "serial_arm",
        "urdf": str(TINY_URDF),
        "srdf": str(TINY_SRDF),
        "tip": None,
        "resolution": 1 / 32,
    }


def test_tiny_fk_by_hand_and_by_matrices(tiny, programs):
    s2, c2 = math.sin(0.2), math.cos(0.2)
    s5, c5 = math.sin(0.5), math.cos(0.5)
    cases = [  # (q, sphere index, world centre worked out by hand)
        ((0, 0, 0, 0), 2, (0.1, 0, 0.25)),
        ((math.pi / 2, 0, 0.1, 0), 4, (0, 0.40, 0.25)),  # link3's sphere, turned to +y
        ((0, -math.pi / 2, 0, 0), 4, (0, -0.30 * s2, 0.25 + 0.30 * c2)),  # up the tilted z
        (
            (0, 0, 0, 0),
            5,
            (
                0.35 + 0.05 * c5 - 0.04 * s5,
                (0.05 * s5 + 0.04 * c5) * c2,
                0.25 + (0.05 * s5 + 0.04 * c5) * s2,
            ),
        ),
    ]
    q = np.array([c[0] for c in cases], np.float32)
    got = np.asarray(programs["centers"](tiny, q))
    for k, (_, s, want) in enumerate(cases):
        np.testing.assert_allclose(got[k, s], want, atol=1e-6)
    q = _uniform(tiny, np.random.default_rng(1), 64)
    np.testing.assert_allclose(programs["centers"](tiny, q), _tiny_centers(q), atol=1e-5)
    # the tool frame as the tip: the wrist frame, then the fixed tool joint
    tool = SerialArm.from_urdf(TINY_URDF, TINY_SRDF, tip="tool")
    np.testing.assert_allclose(
        programs["tip"](tool, q), _tiny_frames(q)[-1] @ _tf(*TINY_TOOL), atol=1e-5
    )
    np.testing.assert_allclose(programs["fk"](tiny, q), np.stack(_tiny_frames(q), 1), atol=1e-5)


@pytest.mark.parametrize("padding", [0.0, 0.03])
def test_tiny_is_valid_matches_oracle(tiny, tiny_world, programs, padding):
    rng = np.random.default_rng(2)
    q = _uniform(tiny, rng, 400, widen=0.05)
    got = np.asarray(programs["valid"](tiny, q, tiny_world, padding))
    radii = [s[3] for s in TINY_SPHERES]
    margin = _oracle_margin(_tiny_centers(q), radii, TINY_PAIRS, tiny_world, padding)
    within = _within(tiny, q)
    sure = ~within | (np.abs(margin) > 1e-4)  # else a float32 tie, not a test of the logic
    assert sure.sum() > 390 and 0 < (~within).sum() < 200
    np.testing.assert_array_equal(got[sure], (within & (margin > 0))[sure])
    assert 0.2 < got.mean() < 0.8  # both outcomes well represented


def test_panda_is_valid_matches_oracle(panda, programs):
    """The obstacle and pair logic on the Panda's 59 spheres (centres from the DH-checked FK)."""
    world = World3D.create(
        BOUNDS,
        spheres=[[0.4, 0.0, 0.5, 0.12], [0.0, 0.45, 0.3, 0.1]],
        cuboids=[
            _cuboid((0.5, -0.3, 0.2), (0.1, 0.15, 0.2), (0.2, 0, 0.4)),
            _cuboid((0, 0, -0.2), (1, 1, 0.05), (0, 0, 0)),
        ],
    )
    q = _uniform(panda, np.random.default_rng(3), 96, widen=0.02)
    got = np.asarray(programs["valid"](panda, q, world, 0.02))
    centers = programs["centers"](panda, q)
    margin = _oracle_margin(centers, panda.sphere_radii, panda.self_pairs, world, 0.02)
    within = _within(panda, q)
    sure = ~within | (np.abs(margin) > 1e-4)
    assert sure.sum() > 90 and 0 < (~within).sum()
    np.testing.assert_array_equal(got[sure], (within & (margin > 0))[sure])
    assert 0.1 < got.mean() < 0.9


def test_invalid_input_and_parts(tiny, tiny_world, programs):
    q = _uniform(tiny, np.random.default_rng(4), 64)
    bad = np.array(
        [[np.nan, 0, 0, 0], [0, 0, np.inf, 0], [3.0, 0, 0, 0], [0, 0, 0.2, 0]], np.float32
    )
    states = np.concatenate([q, bad])
    ok = np.asarray(programs["valid"](tiny, states, tiny_world, 0.0))
    parts = np.asarray(programs["parts"](tiny, states, tiny_world, 0.0))
    assert parts.shape == (len(states), tiny.num_spheres + len(tiny.self_pairs))
    assert not ok[-4:].any() and np.all(parts[-4:] == -1.0)
    assert np.array_equal(ok, np.all(parts > 0, axis=1))
    clearance = jax.jit(jax.vmap(tiny.clearance, in_axes=(0, None, None)), static_argnums=2)(
        q, tiny_world, 0.0
    )
    np.testing.assert_allclose(clearance, parts[:64, : tiny.num_spheres].min(axis=1), atol=1e-6)


# ---------------------------------------------------------------------------
# Sweep bounds and the certified check
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["tiny", "panda"])
def test_sweep_bounds_are_sound(name, request, programs):
    arm = request.getfixturevalue(name)
    rng = np.random.default_rng(5)
    a = _uniform(arm, rng, 24)
    b = np.concatenate(
        [
            _uniform(arm, rng, 12),  # long motions and short ones
            np.clip(a[12:] + rng.normal(0, 0.2, (12, arm.dim)), arm.lower, arm.upper),
        ]
    ).astype(np.float32)
    t = np.linspace(0, 1, 200, dtype=np.float32)
    states = (a[:, None] + t[None, :, None] * (b - a)[:, None]).reshape(-1, arm.dim)
    c = np.asarray(programs["centers"](arm, states), np.float64).reshape(24, 200, -1, 3)
    bound = np.asarray(programs["sweep"](arm, a, b), np.float64)
    s = arm.num_spheres
    moved = np.linalg.norm(c - c[:, :1], axis=-1).max(axis=1)  # (motions, S)
    assert np.all(moved <= bound[:, :s] * (1 + 1e-4) + 1e-5)
    i, k = np.asarray(arm.self_pairs).T
    gap = np.linalg.norm(c[:, :, i] - c[:, :, k], axis=-1)
    changed = np.abs(gap - gap[:, :1]).max(axis=1)
    assert np.all(changed <= bound[:, s:] * (1 + 1e-4) + 1e-5)
    assert np.all(bound[:, s:] <= bound[:, k] + 1e-6)  # a pair's joints are a subset of k's
    moving = bound[:, :s] > 1e-6
    assert (moved[moving] / bound[:, :s][moving]).max() > 0.9  # tight for some sphere


def test_certified_never_frees_a_blocked_motion(tiny, tiny_world):
    rng = np.random.default_rng(6)
    q = _uniform(tiny, rng, 400)
    good = q[_oracle_margin(_tiny_centers(q), tiny.sphere_radii, TINY_PAIRS, tiny_world, 0) > 0]
    a, b = good[:48], np.clip(good[48:96] * 0.3 + good[:48] * 0.7, tiny.lower, tiny.upper)
    b = b.astype(np.float32)

    @jax.jit
    def checks(a, b):  # coordinate-major, as the batched entry points call them
        return (
            tiny.certified_steer_to_batch(a.T, b.T, tiny_world, 0.0),
            tiny.steer_to_batch(a.T, b.T, tiny_world, 0.0),
        )

    cert, disc = map(np.asarray, checks(a, b))
    assert 0 < cert.sum() < len(a) and np.all(~cert | disc)
    t = np.linspace(0, 1, 400)[:, None]
    for k in np.flatnonzero(cert):
        dense = a[k].astype(np.float64) + t * (b[k] - a[k])
        margin = _oracle_margin(
            _tiny_centers(dense), tiny.sphere_radii, TINY_PAIRS, tiny_world, 0.0
        )
        assert margin.min() > 0, (k, margin.min())


# ---------------------------------------------------------------------------
# Parser refusals
# ---------------------------------------------------------------------------

TINY_TEXT = TINY_URDF.read_text()

REFUSALS = [  # (replace this, by this, a fragment of the message)
    (
        '<limit lower="-2.5" upper="2.5" effort="10" velocity="1"/>',
        "",
        "has no <limit lower= upper=>",
    ),
    ('name="j2" type="revolute"', 'name="j2" type="floating"', "has type 'floating'"),
    ('<sphere radius="0.03"/>', '<box size="0.1 0.1 0.1"/>', "is a <box>"),
    (
        '<mesh filename="wrist.stl"/></geometry></collision>',
        '<mesh filename="wrist.stl"/></geometry></collision>'
        '<collision><geometry><sphere radius="0.01"/></geometry></collision>',
        "mixes 1 spheres",
    ),
    ('<parent link="link2"/>', '<parent link="nope"/>', "which is not a <link>"),
    ('lower="-2.2" upper="2.2"', 'lower="2.2" upper="-2.2"', "lower must be below upper"),
    ('<origin xyz="0.25 0 0"/>', '<origin xyz="0.25 0"/>', "give 3 finite numbers"),
    ('<sphere radius="0.06"/>', '<sphere radius="0"/>', "give a radius > 0"),
    ('<sphere radius="0.06"/>', "<sphere/>", "has no radius="),
    ("</robot>", '<link name="loose"/></robot>', "2 links are no joint's child"),
    ('<axis xyz="1 0 0"/>', '<axis xyz="1 0 0"/><mimic joint="j2"/>', "with <mimic>"),
    ('<axis xyz="1 0 0"/>', '<axis xyz="0 0 0"/>', "has the zero axis"),
    ("</robot>", "", "not well-formed XML"),
]


@pytest.mark.parametrize("old,new,fragment", REFUSALS)
def test_parser_refusals(tmp_path, old, new, fragment):
    assert old in TINY_TEXT
    path = tmp_path / "arm.urdf"
    path.write_text(TINY_TEXT.replace(old, new, 1))
    with pytest.raises(ValueError) as e:
        read_arm(path)
    msg = str(e.value)
    assert fragment in msg and "\n" not in msg and msg.startswith(str(path)) and "fix:" in msg


def test_parser_refusals_of_arguments_and_srdf(tmp_path):
    cases = [
        (lambda: read_arm(tmp_path / "missing.urdf"), "no such file"),
        (lambda: read_arm(TINY_URDF, tip="nope"), "the tip 'nope' is not a <link>"),
        # link3's sphere moves through j3, off the chain from base to link2
        (lambda: read_arm(TINY_URDF, tip="link2"), "moves through the joint 'j3'"),
        (lambda: read_arm(TINY_URDF, tip="base"), "has no movable joint"),
    ]
    srdf = tmp_path / "bad.srdf"
    srdf.write_text('<robot name="x"><disable_collisions link1="base" link2="elbow"/></robot>')
    cases.append((lambda: read_arm(TINY_URDF, srdf), "link2='elbow', not a link of"))
    for call, fragment in cases:
        with pytest.raises(ValueError) as e:
            call()
        msg = str(e.value)
        assert fragment in msg and "\n" not in msg and "fix:" in msg, msg


def test_interpolated_states_stay_within_the_joint_limits(panda):
    """float32 ``a + 1 (b - a)`` can land an ulp beyond ``b``: a motion to a state on a
    joint limit must not be blocked by the limit check of its own last state."""
    lo, hi = np.asarray(panda.lower, np.float32), np.asarray(panda.upper, np.float32)
    rng = np.random.default_rng(0)
    a = (lo + rng.random((2000, 7)) * (hi - lo)).astype(np.float32)
    b = a.copy()
    j = np.arange(2000) % 7
    b[np.arange(2000), j] = np.where(np.arange(2000) % 2, hi[j], lo[j])
    plain = a + np.float32(1.0) * (b - a)
    assert ((plain < lo) | (plain > hi)).any()  # the rounding this guards against happens
    t = jnp.linspace(0.0, 1.0, 33)
    states = jax.vmap(lambda x, y: jax.vmap(lambda s: panda.interpolate(x, y, s))(t))(a, b)
    states = np.asarray(states)
    assert ((states >= lo) & (states <= hi)).all()
    np.testing.assert_allclose(states[:, -1], b, atol=1e-6)
    np.testing.assert_array_equal(states[:, 0], a)


def test_gamma_through_shared_programs_equals_the_fused_chunk(tiny, tiny_world):
    """gamma_nt of an arm runs its chunks through the shared batched checks
    (``shared_check_programs``): lane for lane the fused chunk's outcomes, so the
    estimate is the one counted off the fused lanes up to the n-th valid query, whether
    it is read off chunk 0's rows (small n) or counts whole chunks."""
    from ntq_jax import gamma

    key, size = jax.random.key(3), 2048
    lanes = [
        [
            np.asarray(x)
            for x in gamma._fused_chunk_lanes(
                tiny, tiny_world, prng.stream_seeds(key, i), jnp.uint32(0), 0.0, size
            )
        ]
        for i in range(3)
    ]
    both, blocked = (np.concatenate(x) for x in zip(*lanes))
    assert 0 < blocked.sum() < both.sum() < len(both)  # every outcome occurs
    shared = gamma._gamma_chunk_lanes(
        tiny, tiny_world, prng.stream_seeds(key, 1), jnp.uint32(0), 0.0, size
    )
    np.testing.assert_array_equal(shared[0], lanes[1][0])
    np.testing.assert_array_equal(shared[1], lanes[1][1])
    for n in (10, int(both[: 2 * size].sum()) + 5):  # chunk 0's first rows; three chunks
        est = gamma.gamma_nt(tiny, tiny_world, key, n, 0.0, chunk=size)
        last = int(np.flatnonzero(both)[n - 1])
        assert (est.queries, est.non_trivial, est.candidates) == (
            n,
            int(blocked[: last + 1].sum()),
            last + 1,
        ), n
