"""The Panda's validity and certified motion check against independent references.

Imported by ``benchmarks/bench_panda.py`` (``check``: all 7 scenes at full size) and by
``tests/test_panda_checks.py`` (one scene, a few hundred cases); no ``common`` import, so
a test can load it by path.

Validity against coal (:func:`compare_validity`). For each configuration the 59 sphere
centres come from our forward kinematics (``SerialArm.sphere_centers``, float32, turned
to float64); coal gets them as ``coal.Sphere(r)`` at those centres and the scene's
obstacles as ``coal.Box`` / ``coal.Sphere`` / ``coal.Capsule`` with float64 poses. The
reference margin of a configuration is the minimum of

* ``coal.distance(sphere, obstacle) - padding`` (signed distance) over every
  (sphere, obstacle) pair whose centre lies within ``r + padding + NEAR`` of the
  obstacle's axis-aligned bounding box (coal's ``CollisionObject.getAABB``, computed in
  NumPy float64 for all pairs); every other pair is farther than ``NEAR`` from touching
  (the box contains the obstacle), so its margin cannot decide the sign;
* ``coal.distance(sphere_i, sphere_k)`` over every checked self pair
  (``SerialArm.self_pairs``) whose centre distance minus ``r_i + r_k`` (NumPy float64) is
  below ``NEAR``; the others are farther apart than ``NEAR``.

Reference: obstacle-free iff the obstacle margin ``> 0``, self-collision-free iff the self
margin ``> 0``, valid iff both (all configurations are within the joint limits). Ours:
``Env.is_valid``, ``all(spheres_clearance > 0)`` and ``SerialArm.self_collision_free``
(each from ``q`` itself, not from the reference's centres). A disagreement counts when
the answers differ and the reference margin is outside ``[-BAND, BAND]``; those inside
the band are counted apart.

Configurations (:func:`sample_configs`): half uniform in the joint box, half near the
boundary of the valid set: a uniform valid and a uniform invalid configuration, bisected
``BISECT`` times along their segment with ``Env.is_valid``, the valid end moved by a
random direction of length ``10^U(-6, -2)`` rad (so margins from ~1e-7 to ~1e-2 m).

Certified check against a dense discretised check (:func:`compare_certified`): a motion
is dense-free when every state ``k / n``, ``n = ceil(|b - a| / DENSE_STEP)``, is valid by
the one-state kernel (``jax.vmap(SerialArm.is_valid)``); ``DENSE_STEP = 1/640`` rad is 20x
finer than the discretised check's 1/32. The states are interpolated in float64 and rounded
to float32 (so the state at ``t = 1`` is ``b`` itself: the float32 ``a + 1 * (b - a)`` can
round past a joint limit that ``b`` lies on, and is then invalid). A false free is a motion that
``Env.steer_to(check="certified")`` calls free and the dense check blocked: must be 0.
Motions (:func:`sample_motions`), a third each: ``short`` (a uniform valid state to a
valid one ``U(0.02, 0.5)`` rad away in a random direction), ``pair`` (two uniform valid
states), ``graze`` (a valid state ``10^U(-3, -1)`` rad from the boundary of the valid set, found
as in :func:`sample_configs`, to a valid one ``U(0.02, 0.3)`` rad away).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ntq_jax.geometry import spheres_clearance

BAND = 1e-6  # reference margins within this of 0 are not counted as disagreements
NEAR = 1e-3  # metres: pairs farther than this from touching by the NumPy bounds skip coal
BISECT = 24  # bisection steps towards the boundary of the valid set
DENSE_STEP = 1.0 / 640.0  # rad: the dense check's state spacing (20x finer than 1/32)
DENSE_CHUNK = 1 << 15  # states per compiled call of the dense check
GRAZE_SCALE = (-3.0, -1.0)  # log10 rad: how far the graze motions start from the boundary
SAMPLE_CHUNK = 4096  # states per compiled call of the samplers' validity checks


# ---------------------------------------------------------------------------
# coal's side
# ---------------------------------------------------------------------------


def coal_obstacles(world):
    """``[(geometry, Transform3s, aabb_lo (3,), aabb_hi (3,))]`` of the world's rows, float64."""
    import coal

    out = []
    for kind in ("spheres", "cuboids", "capsules"):
        for row in np.asarray(getattr(world, kind), np.float64):
            geom, tf = _coal_shape(coal, kind, row)
            obj = coal.CollisionObject(geom, tf)
            obj.computeAABB()
            box = obj.getAABB()
            out.append(
                (geom, tf, np.asarray(box.min_, np.float64), np.asarray(box.max_, np.float64))
            )
    return out


def _coal_shape(coal, kind, r):
    if kind == "spheres":
        return coal.Sphere(r[3]), coal.Transform3s(np.eye(3), r[:3])
    if kind == "cuboids":
        u, _, vt = np.linalg.svd(r[6:].reshape(3, 3))  # the float32 rows' nearest rotation
        return coal.Box(*(2.0 * r[3:6])), coal.Transform3s(u @ vt, r[:3])
    a, b = r[:3], r[3:6]
    length = float(np.linalg.norm(b - a))
    rot = np.eye(3)
    if length > 0:
        z = (b - a) / length
        x = np.cross(z, [1.0, 0, 0] if abs(z[0]) < 0.9 else [0, 1.0, 0])
        x /= np.linalg.norm(x)
        rot = np.c_[x, np.cross(z, x), z]
    return coal.Capsule(r[6], length), coal.Transform3s(rot, 0.5 * (a + b))


def sphere_centers(robot, q: np.ndarray, chunk: int = 1 << 14) -> np.ndarray:
    """``(N, S, 3)`` float64: our forward kinematics' sphere centres (float32 kernel)."""
    fk = jax.jit(jax.vmap(robot.sphere_centers))
    parts = [np.asarray(fk(jnp.asarray(q[i : i + chunk]))) for i in range(0, len(q), chunk)]
    return np.concatenate(parts).astype(np.float64)


def coal_margins(robot, world, q: np.ndarray, padding: float) -> dict:
    """The reference margins of ``q`` ``(N, 7)`` (module docstring): ``obstacle`` and
    ``self`` ``(N,)`` float64 (``inf`` where no pair came within ``NEAR``), and how many
    coal calls each took."""
    import coal

    centers = sphere_centers(robot, q)
    radii = np.asarray(robot.sphere_radii, np.float32).astype(np.float64)
    req = coal.DistanceRequest()
    req.enable_signed_distance = True
    res = coal.DistanceResult()
    balls = [coal.Sphere(float(r)) for r in radii]
    tf = coal.Transform3s()
    n = len(q)
    obstacle = np.full(n, np.inf)
    calls = {"obstacle": 0, "self": 0}
    for geom, otf, lo, hi in coal_obstacles(world):
        gap = np.linalg.norm(np.maximum(np.maximum(lo - centers, centers - hi), 0.0), axis=-1)
        rows, spheres = np.nonzero(gap - radii - padding <= NEAR)
        for i, s in zip(rows.tolist(), spheres.tolist()):
            tf.setTranslation(centers[i, s])
            res.clear()
            d = coal.distance(geom, otf, balls[s], tf, req, res) - padding
            if d < obstacle[i]:
                obstacle[i] = d
        calls["obstacle"] += len(rows)
    pairs = np.asarray(robot.self_pairs)
    reach = radii[pairs[:, 0]] + radii[pairs[:, 1]]
    self_m = np.full(n, np.inf)
    other = coal.Transform3s()
    for i0 in range(0, n, 4096):
        c = centers[i0 : i0 + 4096]
        gap = np.linalg.norm(c[:, pairs[:, 0]] - c[:, pairs[:, 1]], axis=-1) - reach
        rows, ps = np.nonzero(gap <= NEAR)
        for i, p in zip(rows.tolist(), ps.tolist()):
            s, k = pairs[p]
            tf.setTranslation(c[i, s])
            other.setTranslation(c[i, k])
            res.clear()
            d = coal.distance(balls[s], tf, balls[k], other, req, res)
            if d < self_m[i0 + i]:
                self_m[i0 + i] = d
        calls["self"] += len(rows)
    return {"obstacle": obstacle, "self": self_m, "coal_calls": calls}


# ---------------------------------------------------------------------------
# our side and the comparison
# ---------------------------------------------------------------------------


def our_answers(env, q: np.ndarray) -> dict:
    """``valid`` (``Env.is_valid``), ``obstacle_free`` and ``self_free`` ``(N,)`` bool."""
    robot, pad = env.robot, env.padding
    radii = jnp.asarray(robot.sphere_radii, jnp.float32)

    def parts(x, world):
        free = jnp.all(spheres_clearance(robot.sphere_centers(x), radii, world, pad) > 0.0)
        return free, robot.self_collision_free(x)

    fn = jax.jit(jax.vmap(parts, in_axes=(0, None)))
    obs, slf = (
        np.concatenate(v)
        for v in zip(
            *[
                [np.asarray(o) for o in fn(jnp.asarray(q[i : i + 8192]), env.world)]
                for i in range(0, len(q), 8192)
            ]
        )
    )
    return {"valid": np.asarray(env.is_valid(q)), "obstacle_free": obs, "self_free": slf}


def compare_validity(env, q: np.ndarray) -> dict:
    """Counts of agreement between ours and coal's on ``q`` (see the module docstring)."""
    ref = coal_margins(env.robot, env.world, q, env.padding)
    ours = our_answers(env, q)
    margin = np.minimum(ref["obstacle"], ref["self"])
    out = {"configs": int(len(q)), "coal_calls": ref["coal_calls"], "band": BAND, "near": NEAR}
    for name, m, got in (
        ("valid", margin, ours["valid"]),
        ("obstacle_free", ref["obstacle"], ours["obstacle_free"]),
        ("self_free", ref["self"], ours["self_free"]),
    ):
        want, sure = m > 0.0, np.abs(m) > BAND
        out[name] = {
            "reference_true": int(want.sum()),
            "disagree": int(np.sum((got != want) & sure)),
            "in_band": int(np.sum(~sure)),
            "disagree_in_band": int(np.sum((got != want) & ~sure)),
        }
    bad = (ours["valid"] != (margin > 0.0)) & (np.abs(margin) > BAND)
    out["disagreeing_configs"] = np.flatnonzero(bad)[:20].tolist()
    ab = np.abs(margin)
    out["margin_below"] = {f"{t:g}": int(np.sum(ab < t)) for t in (1e-5, 1e-4, 1e-3, 1e-2)}
    return out


# ---------------------------------------------------------------------------
# sampling
# ---------------------------------------------------------------------------


def _valid(env, q: np.ndarray) -> np.ndarray:
    """``is_valid`` in fixed chunks of ``SAMPLE_CHUNK`` (one compiled shape for all sampling)."""
    from ntq_jax.robots.batch import valid_states

    return valid_states(
        env.robot, env.world, np.asarray(q, np.float32), env.padding, chunk=SAMPLE_CHUNK
    )


def kernel_valid(env, q: np.ndarray) -> np.ndarray:
    """The one-state kernel ``jax.vmap(SerialArm.is_valid)`` (plain ``jax.jit``) on ``q``
    ``(N, 7)``, in chunks of ``DENSE_CHUNK`` rows (the last one padded)."""
    q = np.asarray(q, np.float32)
    fn = _kernel(env.robot, env.padding)
    pad = -len(q) % DENSE_CHUNK
    q = np.concatenate([q, np.repeat(q[:1], pad, axis=0)]) if pad and len(q) else q
    out = [
        np.asarray(fn(jnp.asarray(q[i : i + DENSE_CHUNK]), env.world))
        for i in range(0, len(q), DENSE_CHUNK)
    ]
    return np.concatenate(out)[: len(q) - pad] if out else np.zeros(0, bool)


@functools.lru_cache(maxsize=None)
def _kernel(robot, padding: float):
    return jax.jit(jax.vmap(lambda x, w: robot.is_valid(x, w, padding), in_axes=(0, None)))


def _uniform(env, rng, n: int) -> np.ndarray:
    lo, hi = (np.asarray(v, np.float64) for v in env.robot.config_bounds(env.world))
    return (lo + rng.random((n, len(lo))) * (hi - lo)).astype(np.float32)


def _clip(env, q):
    lo, hi = (np.asarray(v, np.float32) for v in env.robot.config_bounds(env.world))
    return np.clip(q, lo, hi).astype(np.float32)


def boundary_configs(env, rng, n: int, scale=(-6.0, -2.0)) -> np.ndarray:
    """``n`` valid configurations near the boundary of the valid set (bisection, then a
    step of ``10^U(scale)`` rad in a random direction; those that left it are redrawn)."""
    out = []
    while sum(len(o) for o in out) < n:
        q = _uniform(env, rng, 4 * n + 64)
        ok = _valid(env, q)
        m = min(ok.sum(), (~ok).sum())
        a, b = q[ok][:m].astype(np.float64), q[~ok][:m].astype(np.float64)
        for _ in range(BISECT):
            mid = 0.5 * (a + b)
            good = _valid(env, mid)
            a = np.where(good[:, None], mid, a)
            b = np.where(good[:, None], b, mid)
        u = rng.normal(size=a.shape)
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        p = _clip(env, a + u * 10.0 ** rng.uniform(*scale, (len(a), 1)))
        out.append(p[_valid(env, p)])
    return np.concatenate(out)[:n]


def sample_configs(env, seed: int, n: int) -> np.ndarray:
    """``n`` configurations: ``n // 2`` uniform, the rest near the boundary with a random
    step of ``10^U(-6, -2)`` rad (valid or not)."""
    rng = np.random.default_rng(seed)
    u = _uniform(env, rng, n // 2)
    near = boundary_configs(env, rng, n - n // 2).astype(np.float64)
    d = rng.normal(size=near.shape)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    near = _clip(env, near + d * 10.0 ** rng.uniform(-6, -2, (len(near), 1)))
    return np.concatenate([u, near])


def _valid_uniform(env, rng, n: int) -> np.ndarray:
    out = []
    while sum(len(o) for o in out) < n:
        q = _uniform(env, rng, 2 * n + 64)
        out.append(q[_valid(env, q)])
    return np.concatenate(out)[:n]


def _valid_steps(env, rng, starts: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """For each start, a valid configuration ``U(lo, hi)`` rad away (redrawn until valid)."""
    ends = np.empty_like(starts)
    todo = np.arange(len(starts))
    while len(todo):
        u = rng.normal(size=(len(todo), starts.shape[1]))
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        b = _clip(env, starts[todo] + u * rng.uniform(lo, hi, (len(todo), 1)))
        ok = _valid(env, b)
        ends[todo[ok]] = b[ok]
        todo = todo[~ok]
    return ends


def sample_motions(env, seed: int, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(a, b, kind)``: ``n`` motions between valid states, a third each ``short``,
    ``pair`` and ``graze`` (kind 0, 1, 2; see the module docstring)."""
    rng = np.random.default_rng(seed)
    k = [n // 3, n // 3, n - 2 * (n // 3)]
    a0 = _valid_uniform(env, rng, k[0])
    b0 = _valid_steps(env, rng, a0, 0.02, 0.5)
    p = _valid_uniform(env, rng, 2 * k[1])
    a2 = boundary_configs(env, rng, k[2], GRAZE_SCALE)
    b2 = _valid_steps(env, rng, a2, 0.02, 0.3)
    a = np.concatenate([a0, p[: k[1]], a2])
    b = np.concatenate([b0, p[k[1] :], b2])
    return a, b, np.repeat(np.arange(3, dtype=np.int8), k)


# ---------------------------------------------------------------------------
# dense discretised check and the certified comparison
# ---------------------------------------------------------------------------


def dense_steps(a: np.ndarray, b: np.ndarray, step: float = DENSE_STEP) -> np.ndarray:
    """``n = ceil(|b - a| / step)`` (>= 1) per motion, int64."""
    d = np.linalg.norm(b.astype(np.float64) - a.astype(np.float64), axis=1)
    return np.maximum(np.ceil(d / step), 1).astype(np.int64)


def dense_states(a: np.ndarray, b: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """The states ``a + (k / n) (b - a)``, ``k = 0..n``, of each motion in turn, float32
    (interpolated in float64: ``k = n`` is ``b`` itself)."""
    owner = np.repeat(np.arange(len(a)), steps + 1)
    k = np.arange(owner.size) - np.repeat(np.cumsum(steps + 1) - (steps + 1), steps + 1)
    t = (k / steps[owner])[:, None]
    a64, b64 = a.astype(np.float64)[owner], b.astype(np.float64)[owner]
    return (a64 + t * (b64 - a64)).astype(np.float32)


def dense_free(
    env, a: np.ndarray, b: np.ndarray, step: float = DENSE_STEP
) -> tuple[np.ndarray, int]:
    """``(free (N,) bool, states)``: every state of :func:`dense_states` valid by the
    one-state kernel, and how many states were checked."""
    steps = dense_steps(a, b, step)
    free = np.ones(len(a), bool)
    total = i = 0
    while i < len(a):  # motions i..j-1: about DENSE_CHUNK states (at least one motion)
        j = (
            i
            + 1
            + int(
                np.searchsorted(
                    np.cumsum(steps[i + 1 :] + 1), DENSE_CHUNK - steps[i] - 1, side="right"
                )
            )
        )
        states = dense_states(a[i:j], b[i:j], steps[i:j])
        size = len(states)
        ok = kernel_valid(env, states)
        free[i:j] = np.logical_and.reduceat(ok, np.cumsum(steps[i:j] + 1) - (steps[i:j] + 1))
        total += size
        i = j
    return free, total


def compare_certified(
    env, a: np.ndarray, b: np.ndarray, kind: np.ndarray, discretized: bool = True
) -> dict:
    """Certified (and discretised) ``steer_to`` against the dense check, per motion kind."""
    dense, states = dense_free(env, a, b)
    cert = np.asarray(env.steer_to(a, b, check="certified"))
    disc = np.asarray(env.steer_to(a, b)) if discretized else np.zeros(len(a), bool)
    out = {
        "motions": int(len(a)),
        "dense_step": DENSE_STEP,
        "dense_states": int(states),
        "false_free_motions": np.flatnonzero(cert & ~dense)[:20].tolist(),
    }
    for k, name in enumerate(("short", "pair", "graze", "all")):
        m = kind == k if k < 3 else np.ones(len(a), bool)
        out[name] = {
            "motions": int(m.sum()),
            "dense_free": int(np.sum(dense & m)),
            "certified_free": int(np.sum(cert & m)),
            "certified_false_free": int(np.sum(cert & ~dense & m)),
            "certified_blocked_dense_free": int(np.sum(~cert & dense & m)),
            "discretized_free": int(np.sum(disc & m)),
            "discretized_false_free": int(np.sum(disc & ~dense & m)),
        }
    return out
