"""The 3-D world and its kernels (``World3D``, ``shapes3d``) against coal (float64).

coal (the successor of hpp-fcl) computes the signed distance between a small ball at a
point and a sphere, a box or a capsule. The kernels get the float32 obstacle rows; coal
gets the very same numbers in float64, so the two differ only by the kernels' float32
rounding. Cases within ``1e-5`` of a surface are skipped (coordinates of size ~1: a few
float32 operations round by ~1e-7; the worst disagreement measured on 2e4 cases was
2.5e-7); the others must agree within ``1e-5``, inside the solids too (coal's
sphere-box/sphere-capsule penetration is exact), and have the same sign. Hypothesis
draws the seeds; each example pushes hundreds of random cases through one jitted program.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from ntq_jax import geometry as G
from ntq_jax.geometry import World3D
from ntq_jax.geometry.world3d import quat_to_matrix

coal = pytest.importorskip("coal")

BAND = 1e-5
N_CASES = 256
SETTINGS = settings(
    max_examples=3,
    deadline=None,
    database=None,
    phases=(Phase.explicit, Phase.reuse, Phase.generate),
    suppress_health_check=list(HealthCheck),
)
seeds = st.integers(0, 2**32 - 1)
BOUNDS = [[-1, 1], [-1, 1], [0, 2]]


# ---------------------------------------------------------------------------
# Random obstacles (float32 rows) and their coal twins
# ---------------------------------------------------------------------------


def f32(a):
    return np.asarray(a, np.float32)


def rand_rotations(rng, n):
    return np.array([quat_to_matrix(q) for q in rng.normal(size=(n, 4))]).reshape(n, 3, 3)


def rand_rows(rng, kind, n):
    c = rng.uniform(-1, 1, (n, 3))
    if kind == "sphere":
        return f32(np.c_[c, rng.uniform(0.0, 0.5, n)])
    if kind == "cuboid":
        h = np.exp(rng.uniform(math.log(0.01), math.log(0.6), (n, 3)))
        return f32(np.c_[c, h, rand_rotations(rng, n).reshape(n, 9)])
    d = rng.normal(size=(n, 3)) * rng.uniform(0, 0.6, (n, 1))
    d[rng.random(n) < 0.1] = 0.0  # some capsules are spheres (a == b)
    return f32(np.c_[c - d, c + d, rng.uniform(0.0, 0.4, n)])


def coal_shape(kind, row):
    """``(geometry, Transform3s)`` of one obstacle row, in float64."""
    r = np.asarray(row, np.float64)
    if kind == "sphere":
        return coal.Sphere(r[3]), coal.Transform3s(np.eye(3), r[:3])
    if kind == "cuboid":
        rot = r[6:].reshape(3, 3)
        u, _, vt = np.linalg.svd(rot)  # float32 rounding: coal wants an exact rotation
        return coal.Box(*(2.0 * r[3:6])), coal.Transform3s(u @ vt, r[:3])
    a, b = r[:3], r[3:6]
    axis = b - a
    length = float(np.linalg.norm(axis))
    rot = np.eye(3)
    if length > 0:
        z = axis / length
        x = np.cross(z, [1.0, 0, 0] if abs(z[0]) < 0.9 else [0, 1.0, 0])
        x /= np.linalg.norm(x)
        rot = np.c_[x, np.cross(z, x), z]
    return coal.Capsule(r[6], length), coal.Transform3s(rot, 0.5 * (a + b))


def coal_dist(shape, p, radius=0.0):
    """Signed distance between the ball ``(p, radius)`` and a coal shape."""
    req = coal.DistanceRequest()
    req.enable_signed_distance = True
    return coal.distance(
        shape[0],
        shape[1],
        coal.Sphere(float(radius)),
        coal.Transform3s(np.eye(3), np.asarray(p, np.float64)),
        req,
        coal.DistanceResult(),
    )


def points_near(rng, rows, kind):
    """One point per row, around its solid in the solid's own frame (about half inside)."""
    n = len(rows)
    r = rows.astype(np.float64)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    if kind == "sphere":
        return f32(r[:, :3] + d * rng.uniform(0, 2 * r[:, 3:4] + 0.1))
    if kind == "cuboid":
        local = r[:, 3:6] * rng.uniform(-1.6, 1.6, (n, 3)) + rng.uniform(-0.05, 0.05, (n, 3))
        return f32(r[:, :3] + np.einsum("nij,nj->ni", r[:, 6:].reshape(n, 3, 3), local))
    t = rng.uniform(-0.3, 1.3, (n, 1))
    return f32(r[:, :3] + t * (r[:, 3:6] - r[:, :3]) + d * rng.uniform(0, 2 * r[:, 6:7] + 0.1))


KERNELS = {
    "sphere": jax.jit(jax.vmap(G.point_sphere_dist)),
    "cuboid": jax.jit(jax.vmap(G.point_cuboid_dist)),
    "capsule": jax.jit(jax.vmap(G.point_capsule_dist)),
}
CLEARANCE = jax.jit(G.spheres_clearance)
CLEAR = jax.jit(G.spheres_clear)


# ---------------------------------------------------------------------------
# Signed distances and clearances against coal
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["sphere", "cuboid", "capsule"])
@SETTINGS
@given(seed=seeds)
def test_point_distances_match_coal(kind, seed):
    rng = np.random.default_rng(seed)
    rows = rand_rows(rng, kind, N_CASES)
    pts = points_near(rng, rows, kind)
    got = np.asarray(KERNELS[kind](pts, rows), np.float64)
    want = np.array([coal_dist(coal_shape(kind, r), p) for r, p in zip(rows, pts)])
    out, inside = want > BAND, want < -BAND
    assert out.sum() > N_CASES // 4 and inside.sum() > N_CASES // 20  # both sides drawn
    bad = np.flatnonzero((out | inside) & ~(np.abs(got - want) <= BAND))
    assert bad.size == 0, [(rows[i].tolist(), pts[i].tolist(), got[i], want[i]) for i in bad[:3]]
    bad = np.flatnonzero(inside & ~(got < 0))
    assert bad.size == 0, [(rows[i].tolist(), pts[i].tolist(), got[i], want[i]) for i in bad[:3]]


@pytest.mark.parametrize(
    "counts",
    [(2, 3, 2), (0, 66, 0), (65, 0, 67)],
    ids=["unrolled", "looped-cuboids", "looped-spheres-capsules"],
)
@SETTINGS
@given(seed=seeds, padding=st.sampled_from([0.0, 0.05]))
def test_spheres_clearance_matches_coal(counts, seed, padding):
    rng = np.random.default_rng(seed)
    kinds = ("sphere", "cuboid", "capsule")
    rows = {k: rand_rows(rng, k, n) for k, n in zip(kinds, counts)}
    world = World3D.create(BOUNDS, rows["sphere"], rows["cuboid"], rows["capsule"])
    k = 16
    centers = f32(rng.uniform(-1.3, 1.3, (k, 3)))
    radii = f32(rng.uniform(0.0, 0.2, k))
    got = np.asarray(CLEARANCE(centers, radii, world, padding), np.float64)
    # the stored rotations are the nearest rotations of the given ones: use the world's rows
    stored = {"sphere": world.spheres, "cuboid": world.cuboids, "capsule": world.capsules}
    shapes = [coal_shape(kd, r) for kd in kinds for r in np.asarray(stored[kd])]
    want = np.array(
        [min(coal_dist(s, c, r) for s in shapes) - padding for c, r in zip(centers, radii)]
    )
    # coal's ball-vs-solid distance is dist(centre) - radius outside; compare outside the band
    sure = want > BAND
    assert np.all(np.abs(got[sure] - want[sure]) <= BAND), (got[sure], want[sure])
    assert np.all(got[want < -BAND] < 0)
    # the squared-form predicate: clear exactly where the clearance is > 0 (off ties)
    clear = np.asarray(CLEAR(centers, radii, world, padding))
    off_tie = np.abs(got) > 1e-5
    np.testing.assert_array_equal(clear[off_tie], got[off_tie] > 0)
    assert np.all(clear[want > BAND]) and not np.any(clear[want < -BAND])
    collide = jax.jit(G.spheres_collide)(centers, radii, world, padding)
    assert bool(collide) == (not np.all(clear))


def test_sphere_clearance_is_the_one_ball_case():
    rng = np.random.default_rng(0)
    world = World3D.create(
        BOUNDS,
        rand_rows(rng, "sphere", 2),
        rand_rows(rng, "cuboid", 2),
        rand_rows(rng, "capsule", 2),
    )
    c, r = f32([0.2, -0.1, 0.4]), np.float32(0.1)
    one = jax.jit(G.sphere_clearance)(c, r, world, 0.02)
    assert one.shape == ()
    np.testing.assert_allclose(one, CLEARANCE(c[None], r[None], world, 0.02)[0])


def test_exact_values_by_hand():
    rot = quat_to_matrix([0, 0, math.sin(math.pi / 8), math.cos(math.pi / 8)])  # 45 deg about z
    cub = f32([1, 0, 0, 0.5, 0.1, 0.2, *rot.ravel()])
    # along the box's rotated x axis, 0.25 beyond the face; the centre is 0.1 deep (y face)
    p = f32([1 + 0.75 / math.sqrt(2), 0.75 / math.sqrt(2), 0.0])
    assert float(G.point_cuboid_dist(p, cub)) == pytest.approx(0.25, abs=1e-6)
    assert float(G.point_cuboid_dist(f32([1, 0, 0]), cub)) == pytest.approx(-0.1, abs=1e-6)
    cap = f32([0, 0, 0, 0, 0, 1, 0.1])
    assert float(G.point_capsule_dist(f32([0, 0.5, 0.5]), cap)) == pytest.approx(0.4)
    assert float(G.point_capsule_dist(f32([0, 0, 1.5]), cap)) == pytest.approx(0.4)
    assert float(G.point_sphere_dist(f32([0, 0, 0]), f32([0, 3, 4, 1]))) == pytest.approx(4.0)
    # touching is a collision in both forms (exact binary numbers: no rounding)
    world = World3D.create(
        BOUNDS, [[0, 2, 0, 0.5]], [[0, 0, 0, 0.5, 0.5, 0.5, 1, 0, 0, 0, 1, 0, 0, 0, 1]]
    )
    balls, radii = f32([[0, 0, 0.75], [0, 0, 0.875], [0, 2.75, 0]]), f32([0.25, 0.25, 0.25])
    assert np.asarray(G.spheres_clear(balls, radii, world)).tolist() == [False, True, False]
    assert (np.asarray(G.spheres_clearance(balls, radii, world)) > 0).tolist() == [
        False,
        True,
        False,
    ]
    assert np.asarray(G.spheres_clear(balls, radii, world, 0.125)).tolist() == [False, False, False]


# ---------------------------------------------------------------------------
# Edge cases: no obstacles, NaN/inf input, degenerate solids
# ---------------------------------------------------------------------------


def test_no_obstacles_is_finite_and_clear():
    world = World3D.create(BOUNDS)
    c = G.spheres_clearance(f32([[0, 0, 0], [1, 1, 1]]), f32([0.1, 5.0]), world, 0.3)
    np.testing.assert_array_equal(c, np.float32(G.NO_OBSTACLE_CLEARANCE))
    assert np.all(np.isfinite(c)) and float(c[0]) > 1e29
    assert float(G.sphere_clearance(f32([0, 0, 0]), 0.1, world)) == np.float32(1e30)
    assert not bool(G.spheres_collide(f32([[0, 0, 0]]), f32([0.1]), world))
    assert np.all(np.asarray(G.spheres_clear(f32([[0, 0, 0], [1, 1, 1]]), f32([0.1, 5.0]), world)))


def test_non_finite_input_is_not_clear():
    rng = np.random.default_rng(1)
    world = World3D.create(
        BOUNDS,
        rand_rows(rng, "sphere", 1),
        rand_rows(rng, "cuboid", 1),
        rand_rows(rng, "capsule", 1),
    )
    centers = f32([[np.nan, 0, 0], [0, np.inf, 0], [0.5, 0.5, 0.5], [5, 5, 5]])
    radii = f32([0.1, 0.1, np.nan, 0.1])
    c = np.asarray(CLEARANCE(centers, radii, world, 0.0))
    assert np.all(c[:3] == -np.inf) and np.isfinite(c[3]) and c[3] > 0
    assert np.asarray(CLEAR(centers, radii, world, 0.0)).tolist() == [False, False, False, True]
    assert bool(G.spheres_collide(centers[:1], radii[:1], world))
    assert not bool(G.spheres_collide(centers[3:], radii[3:], world))
    assert np.isnan(float(G.point_cuboid_dist(centers[0], world.cuboids[0])))


def test_degenerate_solids_have_no_nan():
    p = f32([0.0, 0.0, 0.0])
    point_capsule = f32([0, 0, 0, 0, 0, 0, 0])  # a point
    assert float(G.point_capsule_dist(p, point_capsule)) == 0.0
    assert float(G.point_capsule_dist(f32([0, 3, 4]), point_capsule)) == pytest.approx(5.0)
    tiny = f32([0, 0, 0, 1e-8, 0, 0, 0.5])  # |b - a|^2 = 1e-16: taken as the sphere at a
    assert float(G.point_capsule_dist(f32([0, 0, 2]), tiny)) == pytest.approx(1.5)
    flat = f32([0, 0, 0, 0, 0, 0, *np.eye(3).ravel()])  # a cuboid of size 0: a point
    assert float(G.point_cuboid_dist(f32([0, 0, 2]), flat)) == pytest.approx(2.0)
    assert float(G.point_cuboid_dist(p, flat)) == 0.0


# ---------------------------------------------------------------------------
# World3D.create and JSON
# ---------------------------------------------------------------------------

EYE = np.eye(3).ravel().tolist()


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"bounds": [[-1, 1], [-1, 1]]}, "three rows"),
        ({"bounds": [[-1, 1], [-1, 1], [2, 2]]}, "bounds[2]"),
        ({"spheres": [[0, 0, 0]]}, "spheres[0]"),
        ({"spheres": [[0, 0, 0, 1], [0, 0, float("nan"), 1]]}, "spheres[1]"),
        ({"spheres": [[0, 0, 0, -1]]}, "radius must be >= 0"),
        ({"cuboids": [[0, 0, 0, 1, 1, 1, *EYE[:-1]]]}, "cuboids[0]"),
        ({"cuboids": [[0, 0, 0, 1, -1, 1, *EYE]]}, "half extents"),
        (
            {"cuboids": [[0, 0, 0, 1, 1, 1, *EYE], [0, 0, 0, 1, 1, 1, *(2 * np.eye(3)).ravel()]]},
            "cuboids[1] has rotation",
        ),
        ({"cuboids": [[0, 0, 0, 1, 1, 1, *np.diag([1.0, 1, -1]).ravel()]]}, "det +1"),
        ({"capsules": [[0, 0, 0, 1, 1, 1, float("inf")]]}, "capsules[0]"),
        ({"capsules": [[0, 0, 0, 1, 1, 1, True]]}, "capsules[0]"),
        ({"capsules": [[0, 0, 0, 1, 1, 1, -0.1]]}, "radius must be >= 0"),
    ],
)
def test_create_refuses(kwargs, message):
    kwargs = {"bounds": BOUNDS, **kwargs}
    with pytest.raises(ValueError) as e:
        World3D.create(**kwargs)
    assert message in str(e.value) and "\n" not in str(e.value)


def test_create_stores_the_nearest_rotation():
    rot = quat_to_matrix([0.3, -0.2, 0.1, 0.9]) + 3e-5  # within the 1e-4 tolerance
    w = World3D.create(BOUNDS, cuboids=[[0, 0, 0, 1, 1, 1, *rot.ravel()]])
    r = np.asarray(w.cuboids[0, 6:], np.float64).reshape(3, 3)
    np.testing.assert_allclose(r.T @ r, np.eye(3), atol=3e-7)
    assert (w.num_spheres, w.num_cuboids, w.num_capsules) == (0, 1, 0)
    assert w.bounds.dtype == w.cuboids.dtype == jnp.float32


def test_json_round_trip_and_quaternion_form():
    rng = np.random.default_rng(2)
    w = World3D.create(
        BOUNDS,
        rand_rows(rng, "sphere", 2),
        rand_rows(rng, "cuboid", 2),
        rand_rows(rng, "capsule", 1),
    )
    back = World3D.from_json(w.to_json())
    for key in ("bounds", "spheres", "cuboids", "capsules"):
        np.testing.assert_allclose(getattr(back, key), getattr(w, key), atol=1e-7)
    q = [0.0, 0.0, math.sin(0.25), math.cos(0.25)]
    data = {
        "bounds": BOUNDS,
        "cuboids": [
            {"center": [1, 2, 3], "half_extents": [0.1, 0.2, 0.3], "quat_xyzw": q},
            [0, 0, 0, 1, 1, 1, *EYE],
        ],
    }
    w = World3D.from_json(data)
    np.testing.assert_allclose(w.cuboids[0, :6], [1, 2, 3, 0.1, 0.2, 0.3], rtol=1e-6)
    np.testing.assert_allclose(
        np.asarray(w.cuboids[0, 6:]).reshape(3, 3),
        [[math.cos(0.5), -math.sin(0.5), 0], [math.sin(0.5), math.cos(0.5), 0], [0, 0, 1]],
        atol=1e-6,
    )
    assert World3D.from_json({"bounds": BOUNDS}).num_obstacles == 0


@pytest.mark.parametrize(
    "data, message",
    [
        ({"bounds": BOUNDS, "boxes": []}, "unknown World3D key"),
        ({"spheres": []}, "needs 'bounds'"),
        (
            {"bounds": BOUNDS, "cuboids": [{"center": [0, 0, 0], "half_extents": [1, 1, 1]}]},
            "cuboids[0] has keys",
        ),
        (
            {
                "bounds": BOUNDS,
                "cuboids": [
                    {"center": [0, 0, 0], "half_extents": [1, 1, 1], "quat_xyzw": [0, 0, 0, 2]}
                ],
            },
            "unit quaternion",
        ),
        (
            {
                "bounds": BOUNDS,
                "cuboids": [
                    {"center": [0, 0], "half_extents": [1, 1, 1], "quat_xyzw": [0, 0, 0, 1]}
                ],
            },
            "cuboids[0].center",
        ),
    ],
)
def test_from_json_refuses(data, message):
    with pytest.raises(ValueError) as e:
        World3D.from_json(data)
    assert message in str(e.value) and "\n" not in str(e.value)
