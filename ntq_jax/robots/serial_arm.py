"""A serial arm in 3-D read from a URDF: joint-space states, collision spheres, a World3D.

* State: the ``n`` movable joints of the chain (:mod:`ntq_jax.robots.urdf`), radians
  (revolute, continuous) or metres (prismatic); the box :meth:`SerialArm.config_bounds`
  is the joint limits (continuous joints ``[-pi, pi]``, no wrap-around: ``periodic``
  is all False).
* Forward kinematics: ``T_k = T_{k-1} origin_k motion_k(q_k)``, frame 0 the root link
  (the world frame). Written on Python-level 3x3 rotations and translations whose
  constant entries are Python floats: products with the constant 0 and 1 entries of
  the URDF's transforms vanish at trace time, so a state's work is a few dozen
  multiply-adds per joint plus one 3x3 affine map per sphere (grouped by frame).
* Valid (:meth:`SerialArm.is_valid`): ``q`` finite and within the joint limits, every
  collision sphere clear of every obstacle by more than ``padding``
  (:func:`ntq_jax.geometry.spheres_clear`: ``spheres_clearance > 0`` compared in squared
  form, without square roots), and no self-collision: for
  every checked sphere pair (links not disabled by the SRDF, not adjacent, not on the
  same rigid body) ``|c_i - c_k| > r_i + r_k``. ``padding`` does NOT apply to
  self-collision: it is the safety margin to the (uncertain) world, while the arm's
  own geometry is known exactly, and padding it would forbid folded poses the
  spheres already over-approximate. The workspace ``bounds`` are not a constraint
  (as in :class:`~ntq_jax.geometry.World3D`).
* Steering: the straight line in joint space; cost metric: the Euclidean joint
  distance (OMPL's RealVector metric).
* ``steer_to`` checks states at most ``resolution`` apart in that metric. The default
  ``1/32`` is VAMP's: its ``validate_motion`` checks ``rake * ceil(d / rake * 32)``
  states on a motion of joint distance ``d``, i.e. states at most 1/32 rad apart.
  Between two checked states a sphere centre moves at most
  ``sqrt(sum_j R_j^2) * resolution`` (``R_j`` below; :meth:`SerialArm.step_motion`:
  at most 6.0 cm for the Panda's hand), so penetrations deeper than that are always
  found.
* Certified check (:mod:`ntq_jax.robots.certified`): the parts are each sphere against
  the obstacles (clearance = its ``spheres_clearance``) and each checked sphere pair
  (clearance ``|c_i - c_k| - r_i - r_k``, no padding). Sweep bounds
  (Schwarzer-Saha-Latombe): along the straight joint-space motion the centre ``p`` of
  a sphere on frame ``f`` moves with velocity ``sum_{j <= f} dq_j u_j x (p - o_j)``
  (revolute; prismatic ``dq_j u_j``), so its path is at most
  ``D = sum_{j <= f} |dq_j| R_j`` long, ``R_j`` an upper bound, valid for every
  configuration, on the distance of the centre from joint ``j``'s axis (1 for a
  prismatic joint); the ball is determined by its centre, so rotation about the
  centre does not move it. ``R_j`` (:meth:`SerialArm.sweep_radii`): the distance
  from the axis of the first link offset (exact, in joint ``j``'s frame, where the
  axis and that offset are constant; a prismatic next joint's stroke taken at its
  worse end), plus the lengths of the remaining link offsets (and prismatic
  strokes) to the centre (triangle inequality); the centre's own distance from the
  axis when the sphere is on joint ``j``'s link. A pair of spheres on frames
  ``f_i < f_k``: expressed in frame ``f_i`` (distances do not change), sphere ``i`` is
  fixed and sphere ``k`` moves on the sub-chain ``f_i + 1 .. f_k`` only, so the
  pair's clearance drops at most ``sum_{f_i < j <= f_k} |dq_j| R_jk``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from pathlib import Path
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from ntq_jax import geometry
from ntq_jax.geometry import World3D, spheres_clear, spheres_clearance
from ntq_jax.robots import affine, urdf
from ntq_jax.robots.base import DiscretizedSteering, discretized_steer_to_batch
from ntq_jax.robots.certified import CertifiedSteering

Array = jax.Array

PANDA_DIR = Path(__file__).resolve().parent.parent / "assets" / "panda"
#: VAMP's motion-check resolution: 32 states per radian of joint distance.
DEFAULT_RESOLUTION = 1.0 / 32.0
#: Lanes of the discretised check's work queue (:func:`~ntq_jax.robots.base.discretized_steer_to_batch`):
#: an iteration's states (``lanes x 8``) and their sphere centres stay in the core's cache;
#: the queue's 512 lanes ran the Panda's long motions ~15 % slower per CPU second. Lanes
#: only schedule the motions: the answers are the same.
QUEUE_LANES = 64
#: The largest in-place piece of a host batch (:mod:`ntq_jax.robots.rows`) for the arm:
#: 2^14 states' sphere centres (59 x 3 float32 each, ~11 MB) stay in cache through the
#: obstacle passes, where the default 2^20 reads them back from memory. cage/1, 2^20
#: uniform states, one core: ``is_valid`` 0.98e6 -> 1.62e6 per CPU second; the
#: discretised ``steer_to`` unchanged (its work queue already runs in cache). Pieces only
#: schedule rows: the answers are the same.
ROW_PIECE_MAX = 1 << 14


@dataclasses.dataclass(frozen=True)
class SerialArm(DiscretizedSteering, CertifiedSteering):
    """A serial arm with collision spheres (see the module docstring).

    Build it with :meth:`from_urdf` or :meth:`panda`. The fields are those of
    :class:`ntq_jax.robots.urdf.ArmModel` (``sphere_offsets``: the sphere centres in
    their frames), Python scalars and tuples, so the arm is a static argument of
    ``jax.jit``. ``source`` is ``(urdf, srdf, tip)`` as given to :meth:`from_urdf`.
    """

    name: str
    joint_names: tuple[str, ...]
    joint_types: tuple[str, ...]
    joint_origins: tuple[urdf.Transform, ...]
    joint_axes: tuple[tuple[float, float, float], ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    tip_transform: urdf.Transform
    sphere_frames: tuple[int, ...]
    sphere_offsets: tuple[tuple[float, float, float], ...]
    sphere_radii: tuple[float, ...]
    sphere_links: tuple[str, ...]
    self_blocks: tuple[tuple[int, int, int, int], ...]
    resolution: float = DEFAULT_RESOLUTION
    source: tuple = ()
    kind: str = dataclasses.field(default="serial_arm", init=False)
    row_piece_max: ClassVar[int] = ROW_PIECE_MAX
    #: Its checks cost seconds each to compile (the fused kernels of obstacles,
    #: self-collision and the motion checks): stages that would fuse their own copy of
    #: them (``gamma.gamma_nt``'s chunks) run the shared batched programs instead, with
    #: the same answers (:mod:`ntq_jax.gamma`).
    shared_check_programs: ClassVar[bool] = True

    def __post_init__(self):
        n, s = len(self.joint_names), len(self.sphere_radii)
        sizes = [
            len(getattr(self, k))
            for k in ("joint_types", "joint_origins", "joint_axes", "lower", "upper")
        ]
        if (
            sizes != [n] * 5
            or [len(self.sphere_frames), len(self.sphere_offsets), len(self.sphere_links)]
            != [s] * 3
        ):
            raise ValueError("serial_arm: per-joint and per-sphere fields differ in length")
        if list(self.sphere_frames) != sorted(self.sphere_frames) or not all(
            0 <= f <= n for f in self.sphere_frames
        ):
            raise ValueError("serial_arm.sphere_frames must be non-decreasing frames 0..n")
        if not all(0 <= i0 < i1 <= k0 < k1 <= s for i0, i1, k0, k1 in self.self_blocks):
            raise ValueError("serial_arm.self_blocks must be sphere ranges i0 < i1 <= k0 < k1")
        if not (isinstance(self.resolution, (int, float)) and self.resolution > 0):
            raise ValueError(f"serial_arm.resolution is {self.resolution!r}: expected a number > 0")
        object.__setattr__(self, "resolution", float(self.resolution))

    # ------------------------------------------------------------------ construction

    @staticmethod
    def from_model(
        model: urdf.ArmModel, resolution: float = DEFAULT_RESOLUTION, source: tuple = ()
    ) -> "SerialArm":
        """The arm of a model read by :func:`ntq_jax.robots.urdf.read_arm`."""
        js = model.joints
        return SerialArm(
            name=model.name,
            joint_names=tuple(j.name for j in js),
            joint_types=tuple(j.kind for j in js),
            joint_origins=tuple(j.origin for j in js),
            joint_axes=tuple(j.axis for j in js),
            lower=tuple(j.lower for j in js),
            upper=tuple(j.upper for j in js),
            tip_transform=model.tip_transform,
            sphere_frames=model.sphere_frames,
            sphere_offsets=model.sphere_centers,
            sphere_radii=model.sphere_radii,
            sphere_links=model.sphere_links,
            self_blocks=model.self_blocks,
            resolution=resolution,
            source=source,
        )

    @staticmethod
    def from_urdf(
        urdf_path, srdf_path=None, tip: str | None = None, resolution: float = DEFAULT_RESOLUTION
    ) -> "SerialArm":
        """Reads the arm from a URDF (and an SRDF's disabled collision pairs).

        Raises:
            ValueError: one line naming the file, the element and the fix
                (:func:`ntq_jax.robots.urdf.read_arm`).
        """
        model = urdf.read_arm(urdf_path, srdf_path, tip)
        source = (str(urdf_path), None if srdf_path is None else str(srdf_path), tip)
        return SerialArm.from_model(model, resolution, source)

    @staticmethod
    def panda(resolution: float = DEFAULT_RESOLUTION) -> "SerialArm":
        """The Franka Emika Panda of VAMP's spherized URDF (``ntq_jax/assets/panda/``).

        Joints ``panda_joint1..7`` with the URDF's limits; 59 spheres on links 0-7, the
        hand and both fingers. The asset's finger joints are ``fixed`` (at ``y = +-0.065``,
        ``z = 0.0584`` in the hand frame: VAMP's fixed fingers), so the hand and fingers are
        one rigid body with link 7; the tip is ``panda_hand`` (the flange turned by -pi/4).
        """
        return _panda(float(resolution))

    # ------------------------------------------------------------------ the Robot protocol

    @property
    def dim(self) -> int:
        return len(self.joint_names)

    @property
    def num_spheres(self) -> int:
        return len(self.sphere_radii)

    @property
    def periodic(self) -> tuple[bool, ...]:
        """No coordinate wraps around (continuous joints too live in ``[-pi, pi]``)."""
        return (False,) * self.dim

    @property
    def metric_weights(self) -> tuple[float, ...]:
        return (1.0,) * self.dim

    def config_bounds(self, world: World3D | None = None):
        """The joint limits ``(lower, upper)``, each ``(n,)`` float32."""
        return (jnp.asarray(self.lower, jnp.float32), jnp.asarray(self.upper, jnp.float32))

    def longest_motion(self, world: World3D | None = None) -> float:
        """The diagonal of the joint box, the longest motion in the cost metric."""
        return math.sqrt(sum((hi - lo) ** 2 for lo, hi in zip(self.lower, self.upper)))

    def interpolate(self, a: Array, b: Array, t: Array) -> Array:
        """``a + t (b - a)``, kept in the box spanned by ``a`` and ``b``: float32 rounding
        could put it a few ulp outside (``a + 1 (b - a)`` beyond ``b``), and a motion to
        a state on a joint limit would then be blocked by the limit check."""
        return jnp.clip(a + t * (b - a), jnp.minimum(a, b), jnp.maximum(a, b))

    def distance(self, a: Array, b: Array) -> Array:
        return jnp.sqrt(jnp.sum((b - a) ** 2))

    def to_json(self) -> dict:
        """``{"kind": "serial_arm", "urdf", "srdf", "tip", "resolution"}``, or ``"preset":
        "panda"`` for :meth:`panda`."""
        out = {"kind": "serial_arm"}
        if self.source and self.source[0] == "preset:panda":
            out["preset"] = "panda"
        elif self.source:
            out.update(urdf=self.source[0], srdf=self.source[1], tip=self.source[2])
        out["resolution"] = self.resolution
        return out

    def steer_to_batch(
        self, a: Array, b: Array, world: World3D, padding: float, mask: Array | None = None
    ) -> Array:
        """Coordinate-major ``(d, N), (d, N) -> (N,)``: the discretised check's work queue
        on :data:`QUEUE_LANES` lanes (the same answers as ``steer_to``)."""
        return discretized_steer_to_batch(
            self, a, b, world, padding, self.resolution, mask, lanes=QUEUE_LANES
        )

    # ------------------------------------------------------------------ kinematics

    def _frames(self, q: Array) -> list:
        """``(R, t)`` of frames 0..n as Python-level 3x3 / 3 lists (entries float or traced)."""
        rot = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
        pos = [0.0, 0.0, 0.0]
        frames = [(rot, pos)]
        for k, kind in enumerate(self.joint_types):
            o_rot, o_pos = self.joint_origins[k]
            shift = affine.matvec(rot, [float(v) for v in o_pos])
            pos = [affine.add(p, d) for p, d in zip(pos, shift)]
            rot = affine.matmul(rot, affine.rows(o_rot))
            axis = tuple(float(v) for v in self.joint_axes[k])
            if kind == "prismatic":
                direction = affine.matvec(rot, list(axis))
                pos = [affine.add(p, affine.mul(q[k], d)) for p, d in zip(pos, direction)]
            else:
                sin, cos = geometry.sincos(q[k])
                rot = affine.matmul(rot, affine.rotation(axis, sin, cos))
            frames.append((rot, pos))
        return frames

    @staticmethod
    def _homogeneous(rot, pos) -> Array:
        f32 = functools.partial(jnp.asarray, dtype=jnp.float32)
        rows = [[f32(rot[i][j]) for j in range(3)] + [f32(pos[i])] for i in range(3)]
        rows.append([jnp.float32(0.0)] * 3 + [jnp.float32(1.0)])
        return jnp.stack([jnp.stack(r) for r in rows])

    def forward_kinematics(self, q: Array) -> Array:
        """``(n + 1, 4, 4)``: the homogeneous transforms of frames 0 (root) .. n."""
        return jnp.stack([self._homogeneous(r, t) for r, t in self._frames(q)])

    def tip_pose(self, q: Array) -> Array:
        """``(4, 4)``: the tip link's frame (``tip_transform`` after frame n)."""
        rot, pos = self._frames(q)[-1]
        t_rot, t_pos = self.tip_transform
        shift = affine.matvec(rot, [float(v) for v in t_pos])
        pos = [affine.add(p, d) for p, d in zip(pos, shift)]
        return self._homogeneous(affine.matmul(rot, affine.rows(t_rot)), pos)

    def _sphere_xyz(self, q: Array) -> tuple[Array, Array, Array]:
        """Sphere centres as three ``(S,)`` coordinate vectors: one affine map per frame."""
        frames = self._frames(q)
        groups = [[], [], []]
        for f, (rot, pos) in enumerate(frames):
            idx = [i for i, g in enumerate(self.sphere_frames) if g == f]
            if not idx:
                continue
            local = np.asarray([self.sphere_offsets[i] for i in idx], np.float32)  # (S_f, 3)
            for i in range(3):
                const = np.zeros(len(idx), np.float32)
                out = None
                for m in range(3):
                    col = local[:, m]
                    if not np.any(col):
                        continue
                    if affine.is_const(rot[i][m]):
                        const = const + np.float32(rot[i][m]) * col
                    else:
                        term = rot[i][m] * col
                        out = term if out is None else out + term
                if affine.is_const(pos[i]):
                    const = const + np.float32(pos[i])
                    out = const if out is None else out + const
                else:
                    out = pos[i] + const if out is None else out + (pos[i] + const)
                groups[i].append(jnp.asarray(out, jnp.float32))  # (S_f,): const is a vector
        return tuple(jnp.concatenate(g) for g in groups)

    def sphere_centers(self, q: Array) -> Array:
        """``(S, 3)``: the centres of the collision spheres at ``q`` (world frame)."""
        return jnp.stack(self._sphere_xyz(q), axis=1)

    # ------------------------------------------------------------------ validity

    def _q_ok(self, q: Array) -> Array:
        lo, hi = self.config_bounds()
        return jnp.all(jnp.isfinite(q)) & jnp.all((q >= lo) & (q <= hi))

    def _pair_d2(self, x, y, z):
        """Per self block: squared centre distances ``(ni, nk)`` and ``(ri + rk)^2``."""
        r = np.asarray(self.sphere_radii, np.float32)
        out = []
        for i0, i1, k0, k1 in self.self_blocks:
            dx = x[i0:i1, None] - x[None, k0:k1]
            dy = y[i0:i1, None] - y[None, k0:k1]
            dz = z[i0:i1, None] - z[None, k0:k1]
            out.append((dx * dx + dy * dy + dz * dz, (r[i0:i1, None] + r[None, k0:k1]) ** 2))
        return out

    def is_valid(self, q: Array, world: World3D, padding: float) -> Array:
        """Finite, within the joint limits, spheres clear of obstacles by more than
        ``padding``, and no self-collision (no padding there; see the module docstring)."""
        x, y, z = self._sphere_xyz(q)
        ok = self._q_ok(q)
        radii = jnp.asarray(self.sphere_radii, jnp.float32)
        ok = ok & jnp.all(spheres_clear(jnp.stack([x, y, z], axis=1), radii, world, padding))
        return ok & self._self_free(x, y, z)

    def _self_free(self, x, y, z) -> Array:
        ok = jnp.bool_(True)
        for d2, reach2 in self._pair_d2(x, y, z):
            ok = ok & jnp.all(d2 > reach2)
        return ok

    def self_collision_free(self, q: Array) -> Array:
        """True when no checked sphere pair overlaps (limits and obstacles not looked at)."""
        return self._self_free(*self._sphere_xyz(q))

    @property
    def self_pairs(self) -> tuple[tuple[int, int], ...]:
        """The checked sphere pairs ``(i, k)``, in the order of the pair parts."""
        return tuple(
            (i, k)
            for i0, i1, k0, k1 in self.self_blocks
            for i in range(i0, i1)
            for k in range(k0, k1)
        )

    # ------------------------------------------------------------------ certified check

    def part_clearances(self, q: Array, world: World3D, padding: float) -> Array:
        """``(S + P,)``: each sphere's obstacle clearance (``spheres_clearance``, minus
        ``padding``), then each checked pair's ``|c_i - c_k| - r_i - r_k`` (in
        :attr:`self_pairs` order); all ``> 0`` iff ``q`` is valid (up to float32 rounding
        within about 1e-7 of touching: ``is_valid`` compares squared distances); all -1 for
        non-finite ``q`` or one outside the joint limits."""
        x, y, z = self._sphere_xyz(q)
        radii = jnp.asarray(self.sphere_radii, jnp.float32)
        parts = [spheres_clearance(jnp.stack([x, y, z], axis=1), radii, world, padding)]
        r = np.asarray(self.sphere_radii, np.float32)
        for (d2, _), (i0, i1, k0, k1) in zip(self._pair_d2(x, y, z), self.self_blocks):
            parts.append((jnp.sqrt(d2) - (r[i0:i1, None] + r[None, k0:k1])).ravel())
        c = jnp.concatenate(parts)
        ok = self._q_ok(q) & jnp.all(jnp.isfinite(c))
        return jnp.where(ok, c, -1.0)

    def clearance(self, q: Array, world: World3D, padding: float) -> Array:
        """The spheres' distance to the nearest obstacle minus ``padding`` (the minimum of
        the sphere parts of :meth:`part_clearances`): ``> 0`` iff no sphere is within
        ``padding`` of an obstacle. Self-collision is NOT in it (it is in the pair parts
        and :meth:`is_valid`); -1 for non-finite ``q`` or one outside the joint limits."""
        return jnp.min(self.part_clearances(q, world, padding)[: self.num_spheres])

    @functools.cached_property
    def _radii_table(self) -> np.ndarray:
        return self.sweep_radii()

    def sweep_radii(self) -> np.ndarray:
        """``(S, n)`` float64: ``R[s, j]`` bounds the distance of sphere ``s``'s centre from
        joint ``j``'s axis over all configurations (1 for a prismatic joint, 0 for joints
        after the sphere's frame); see the module docstring."""
        n, s = self.dim, self.num_spheres
        offsets = [np.asarray(o[1], np.float64) for o in self.joint_origins]
        rots = [np.asarray(o[0], np.float64).reshape(3, 3) for o in self.joint_origins]
        axes = [np.asarray(a, np.float64) for a in self.joint_axes]
        stroke = [
            max(abs(lo), abs(hi)) if kind == "prismatic" else 0.0
            for kind, lo, hi in zip(self.joint_types, self.lower, self.upper)
        ]
        table = np.zeros((s, n))
        for si in range(s):
            f = self.sphere_frames[si]
            c = np.asarray(self.sphere_offsets[si], np.float64)
            for j in range(f):  # joint j + 1 (0-based j) moves frames j + 1 .. n
                if self.joint_types[j] == "prismatic":
                    table[si, j] = 1.0
                    continue
                u = axes[j]

                def off_axis(v):
                    return float(np.linalg.norm(v - np.dot(v, u) * u))

                if f == j + 1:  # the sphere is on this joint's link
                    table[si, j] = off_axis(c)
                    continue
                # first offset, to joint j + 2's origin (and its stroke), exact in frame j + 1
                a = offsets[j + 1]
                if self.joint_types[j + 1] == "prismatic":
                    d = rots[j + 1] @ axes[j + 1]
                    lo, hi = self.lower[j + 1], self.upper[j + 1]
                    first = max(off_axis(a + lo * d), off_axis(a + hi * d))
                else:
                    first = off_axis(a)
                rest = sum(float(np.linalg.norm(offsets[k])) + stroke[k] for k in range(j + 2, f))
                table[si, j] = first + rest + float(np.linalg.norm(c))
        return table

    def part_sweep_bounds(self, a: Array, b: Array) -> Array:
        """``(S + P,)``, in :meth:`part_clearances` order: how far each sphere centre can
        move from ``a`` to ``b`` (``sum_j R_sj |dq_j|``), and how much each pair's distance
        can change (``sum_{f_i < j <= f_k} R_kj |dq_j|``)."""
        dq = jnp.abs(b - a)
        table = self._radii_table.astype(np.float32)  # (S, n)
        sphere = jnp.sum(jnp.asarray(table) * dq[None, :], axis=1)
        parts = [sphere]
        frames = np.asarray(self.sphere_frames)
        for i0, i1, k0, k1 in self.self_blocks:
            # frames are non-decreasing, so f_i <= f_k; the joints after frame f_i only
            rel = table[k0:k1].copy()
            rel[:, : frames[i0]] = 0.0  # a block's rows are on one frame
            pair = jnp.sum(jnp.asarray(rel) * dq[None, :], axis=1)  # (nk,)
            parts.append(jnp.broadcast_to(pair[None, :], (i1 - i0, k1 - k0)).ravel())
        return jnp.concatenate(parts)

    def step_motion(self) -> float:
        """How far a sphere centre can move between two states ``resolution`` apart:
        ``max_s sqrt(sum_j R_sj^2) * resolution`` (Cauchy-Schwarz on the sweep bound)."""
        return float(np.max(np.sqrt(np.sum(self._radii_table**2, axis=1)))) * self.resolution


@functools.lru_cache(maxsize=None)
def _panda(resolution: float) -> SerialArm:
    arm = SerialArm.from_urdf(
        PANDA_DIR / "panda_spherized.urdf",
        PANDA_DIR / "panda.srdf",
        tip="panda_hand",
        resolution=resolution,
    )
    return dataclasses.replace(arm, source=("preset:panda", None, "panda_hand"))
