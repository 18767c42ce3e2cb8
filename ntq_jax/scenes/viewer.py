"""Figures of a 3-D scene with an arm at a few states (matplotlib 3-D, Agg backend).

* :func:`draw_scene`: the obstacles of a :class:`~ntq_jax.geometry.World3D` (cuboids as
  boxes with their rotation, capsules as cylinders with hemispherical caps, spheres) and
  the arm's collision spheres at given joint states (by default the start and goal of
  ``env.query``), or along a path (a few states spread along it, faded, more opaque
  towards the goal, and the hand's trace); returns the figure.
* :func:`save`: writes the figure atomically (:func:`ntq_jax.artifacts.save_figure`) and
  closes it.

::

    from ntq_jax.scenes import viewer
    env = ntq_jax.make_env("panda/cage/1")
    viewer.save(viewer.draw_scene(env), "cage_1.png")

Everything drawn is one ``Poly3DCollection`` of shaded faces, so that matplotlib's
painter's sort sees the arm and the obstacles together (it sorts the faces of one
collection by depth; separate collections are drawn whole, one over the other, and
the arm would show through a shelf). The sort is per face, not per pixel, so a few
faces may still overlap wrongly where two objects touch. The axes are scaled equally
(a metre is as long on every axis) and fitted to what is drawn.

Spheres of an arm state that touch an obstacle (clearance ``<= padding``,
:func:`ntq_jax.geometry.spheres_clearance`, the environment's padding) are drawn red
with ``mark_collisions`` (also in a path's faded states); self-collision is not marked.

matplotlib is imported on the first call (with the Agg backend if none was chosen);
nothing here prints: progress is a ``progress=`` bar factory (:mod:`ntq_jax.progress`),
notes go to ``log`` (a callable taking a string) when given.
"""

from __future__ import annotations

import functools
import math
import sys
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from ntq_jax import artifacts
from ntq_jax.progress import Progress, open_bar

__all__ = ["draw_scene", "save", "auto_view", "world_quads", "OBSTACLE_COLOR", "STATE_COLORS"]

#: The elevation of :func:`auto_view`, in degrees.
DEFAULT_ELEVATION = 25.0
#: How far :func:`auto_view` turns from looking straight from the robot's base at the
#: obstacles, in degrees: enough that the arm does not hide what it reaches into.
VIEW_TURN = 30.0
#: The obstacles' colour.
OBSTACLE_COLOR = "#8c96a6"
#: The obstacles' opacity: low enough to see the arm inside a shelf or a cage.
OBSTACLE_ALPHA = 0.35
#: Colours of the arm states drawn, in turn (the first two: start and goal).
STATE_COLORS = ("#2a9d55", "#e07b1a", "#6a4c93", "#1f77b4", "#c9a227", "#17becf")
#: The colour of a path's intermediate states and of the hand's trace.
PATH_COLOR = "#3b6fd4"
#: The colour of a sphere that touches an obstacle (``mark_collisions``).
COLLISION_COLOR = "#d62728"
#: The light's direction (from the viewer's upper left), for the faces' shading.
_LIGHT = np.array([-0.4, -0.5, 0.77])


def _plt():
    import matplotlib

    if "matplotlib.pyplot" not in sys.modules:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


# ---------------------------------------------------------------------------------------
# Meshes: (F, 4, 3) quads (a degenerate quad is a triangle)
# ---------------------------------------------------------------------------------------


def _grid_quads(p: np.ndarray) -> np.ndarray:
    """The quads of a ``(rows, cols, 3)`` grid of points (columns wrap around)."""
    q = np.stack([p[:-1], np.roll(p[:-1], -1, axis=1), np.roll(p[1:], -1, axis=1), p[1:]], axis=2)
    return q.reshape(-1, 4, 3)


def _sphere_quads(center, radius: float, n: int) -> np.ndarray:
    lat = np.linspace(-math.pi / 2, math.pi / 2, max(n // 2, 2) + 1)
    lon = np.linspace(0, 2 * math.pi, n, endpoint=False)
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    unit = np.stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)], axis=-1)
    return _grid_quads(np.asarray(center, np.float64) + radius * unit)


def _frame(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors perpendicular to the unit ``axis`` and to each other."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(axis, u)


def _capsule_quads(a, b, radius: float, n: int) -> np.ndarray:
    """A cylinder from ``a`` to ``b`` with a hemisphere at each end (one closed grid)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    length = float(np.linalg.norm(b - a))
    if length < 1e-9:
        return _sphere_quads(a, radius, n)
    axis = (b - a) / length
    u, v = _frame(axis)
    half = max(n // 4, 2)
    lat = np.concatenate(
        [np.linspace(-math.pi / 2, 0, half + 1), np.linspace(0, math.pi / 2, half + 1)]
    )
    ends = np.concatenate([np.zeros(half + 1), np.ones(half + 1)])  # 0: around a, 1: around b
    lon = np.linspace(0, 2 * math.pi, n, endpoint=False)
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    base = np.where(ends[:, None, None] > 0, b, a)  # (rows, 1, 3)
    ring = np.cos(lo)[..., None] * u + np.sin(lo)[..., None] * v
    p = base + radius * (np.cos(la)[..., None] * ring + np.sin(la)[..., None] * axis)
    return _grid_quads(p)


def _cuboid_quads(row) -> np.ndarray:
    """The 6 faces of ``[cx, cy, cz, hx, hy, hz, R (row-major)]``."""
    row = np.asarray(row, np.float64)
    c, h, rot = row[:3], row[3:6], row[6:15].reshape(3, 3)
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], np.float64)
    corners = c + (signs * h) @ rot.T  # R's columns are the box axes in the world
    faces = [(0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5)]
    return corners[np.array(faces)]


def world_quads(world, n: int = 24) -> np.ndarray:
    """``(F, 4, 3)``: the faces of every obstacle of ``world`` (``n`` faces around a round
    solid)."""
    parts = [np.zeros((0, 4, 3))]
    parts += [_cuboid_quads(r) for r in np.asarray(world.cuboids, np.float64)]
    parts += [
        _capsule_quads(r[:3], r[3:6], float(r[6]), n)
        for r in np.asarray(world.capsules, np.float64)
    ]
    parts += [_sphere_quads(r[:3], float(r[3]), n) for r in np.asarray(world.spheres, np.float64)]
    return np.concatenate(parts)


def auto_view(world) -> tuple[float, float]:
    """``(elevation, azimuth)`` in degrees looking from behind the robot's base (the origin)
    towards the obstacles' centre, turned by :data:`VIEW_TURN`, from
    :data:`DEFAULT_ELEVATION` above (MotionBenchMaker's shelves, cages and tables stand on
    different sides of the robot)."""
    centres = [
        np.asarray(world.cuboids, np.float64)[:, :3],
        np.asarray(world.spheres, np.float64)[:, :3],
        (
            np.asarray(world.capsules, np.float64)[:, :3]
            + np.asarray(world.capsules, np.float64)[:, 3:6]
        )
        / 2,
    ]
    c = np.concatenate(centres)
    if not len(c) or np.hypot(*c[:, :2].mean(axis=0)) < 1e-6:
        return DEFAULT_ELEVATION, -60.0 + VIEW_TURN  # matplotlib's default azimuth, turned
    cx, cy = c[:, :2].mean(axis=0)
    azim = math.degrees(math.atan2(-cy, -cx)) + VIEW_TURN
    return DEFAULT_ELEVATION, (azim + 180.0) % 360.0 - 180.0


def _shade(quads: np.ndarray, rgba: np.ndarray) -> np.ndarray:
    """Per-face colours lit by :data:`_LIGHT` (Lambert plus ambient, two-sided)."""
    e1 = quads[:, 2] - quads[:, 0]
    e2 = quads[:, 3] - quads[:, 1]
    normal = np.cross(e1, e2)
    norm = np.linalg.norm(normal, axis=1, keepdims=True)
    normal = np.divide(normal, norm, out=np.zeros_like(normal), where=norm > 0)
    light = _LIGHT / np.linalg.norm(_LIGHT)
    k = 0.55 + 0.45 * np.abs(normal @ light)
    out = np.array(rgba, np.float64, copy=True)
    out[:, :3] *= k[:, None]
    return out


# ---------------------------------------------------------------------------------------
# The arm
# ---------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=8)
def _arm_kernel(robot):
    """``(q (k, d), world, padding) -> centres (k, S, 3), clearances (k, S)``, compiled."""
    import jax
    import jax.numpy as jnp

    from ntq_jax.geometry import spheres_clearance

    radii = jnp.asarray(robot.sphere_radii, jnp.float32)

    def one(q, world, padding):
        c = robot.sphere_centers(q)
        return c, spheres_clearance(c, radii, world, 0.0) - padding

    return jax.jit(jax.vmap(one, in_axes=(0, None, None)))


@functools.lru_cache(maxsize=8)
def _tip_kernel(robot):
    """``q (k, d) -> (k, 3)``: the tip link's origin, compiled."""
    import jax

    return jax.jit(jax.vmap(lambda q: robot.tip_pose(q)[:3, 3]))


def _along(path: np.ndarray, count: int) -> np.ndarray:
    """``count`` states spread evenly by joint distance along the polyline ``path``."""
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] <= 0:
        return np.repeat(path[:1], count, axis=0)
    t = np.linspace(0.0, s[-1], count)
    return np.stack([np.interp(t, s, path[:, j]) for j in range(path.shape[1])], axis=1)


def _states(x, d: int, what: str) -> np.ndarray:
    a = np.asarray(x, np.float64)
    if a.ndim == 1:
        a = a[None]
    if a.ndim != 2 or a.shape[1] != d:
        raise ValueError(
            f"{what} must be (k, {d}) joint states (or one (d,) state), got shape {a.shape}"
        )
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{what} holds non-finite joint values")
    return a


# ---------------------------------------------------------------------------------------
# The figure
# ---------------------------------------------------------------------------------------


def draw_scene(
    env,
    states=None,
    path=None,
    ax=None,
    *,
    labels: Sequence[str] | None = None,
    path_states: int = 6,
    title: str | None = None,
    view: tuple[float, float] | None = None,
    mark_collisions: bool = True,
    resolution: int = 24,
    arm_resolution: int = 10,
    figsize=(6.4, 5.6),
    legend: bool = True,
    limits=None,
    progress: Progress = None,
    log: Callable[[str], None] | None = None,
):
    """Draws ``env``'s obstacles and its arm at ``states`` (and along ``path``); returns the
    figure.

    Args:
        env: an :class:`~ntq_jax.envs.Env` with a :class:`~ntq_jax.geometry.World3D` and an
            arm with ``sphere_centers`` (a :class:`~ntq_jax.robots.SerialArm`).
        states: ``(k, d)`` joint states (or one ``(d,)``), each drawn in its own colour of
            :data:`STATE_COLORS`; None: ``path``'s first and last state if a path is given,
            else ``env.query`` (start and goal) if it has one, else none.
        path: ``(m, d)`` joint-space waypoints: ``path_states`` states spread evenly along
            it by joint distance are drawn faded (more opaque towards the goal; its
            endpoints are the ``states`` above unless given), and the trace of the hand
            (the tip link's origin) along it as a line.
        ax: a 3-D axes to draw on (``fig.add_subplot(projection="3d")``); None: a new
            figure of ``figsize``.
        labels: one legend label per state; default ``start``, ``goal`` for the default
            states, else ``state 0``, ``state 1``, ...
        title: the axes' title; default ``env.name``.
        view: ``(elevation, azimuth)`` in degrees; None: :func:`auto_view`.
        mark_collisions: draw red the spheres that touch an obstacle (see the module
            docstring).
        resolution, arm_resolution: faces around a round obstacle and an arm sphere.
        legend: draw the legend (states, path, obstacles).
        limits: ``[[xmin, xmax], [ymin, ymax], [zmin, zmax]]`` shown (made a cube, so a metre
            is as long on every axis); None: everything drawn; ``"bounds"``: the world's
            ``bounds``.
        progress: a bar factory (:mod:`ntq_jax.progress`), counting the states drawn.
        log: called with one line per note (e.g. how many faces were drawn).

    Raises:
        ValueError: a planar environment, states of the wrong shape or non-finite, bad
            ``limits``.
    """
    from ntq_jax.geometry import World3D

    world, robot = env.world, env.robot
    if not isinstance(world, World3D) or not hasattr(robot, "sphere_centers"):
        raise ValueError(
            f"{getattr(env, 'name', env)!r}: draw_scene draws a 3-D world with an "
            "arm of collision spheres; draw a planar map with "
            "ntq_jax.plotting.draw_map"
        )
    d = robot.dim
    states, labels, path, ghosts = _drawn_states(env, d, states, path, labels, path_states)
    box = None if limits is None else _limits(limits, world)

    plt = _plt()
    from matplotlib.colors import to_rgba
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    if ax is None:
        fig = plt.figure(figsize=figsize)
        ax = fig.add_subplot(projection="3d")
    fig = ax.figure
    bar = open_bar(
        progress,
        desc=f"draw {getattr(env, 'name', '')}",
        total=len(states) + len(ghosts),
        unit="state",
    )

    quads = [world_quads(world, resolution)]
    colors = [np.tile(to_rgba(OBSTACLE_COLOR, OBSTACLE_ALPHA), (len(quads[0]), 1))]
    unit = _sphere_quads(np.zeros(3), 1.0, arm_resolution)
    radii = np.asarray(robot.sphere_radii, np.float64)
    arm_quads = unit[None] * radii[:, None, None, None]  # (S, F, 4, 3)

    drawn = np.concatenate([ghosts, states]) if len(ghosts) + len(states) else np.zeros((0, d))
    with bar:
        touching = _arm_faces(
            env, drawn, len(ghosts), arm_quads, mark_collisions, quads, colors, bar
        )
    faces = np.concatenate(quads)
    face_colors = _shade(faces, np.concatenate(colors))
    coll = Poly3DCollection(
        faces, facecolors=face_colors, edgecolors="none", linewidths=0, zsort="average"
    )
    ax.add_collection3d(coll)

    handles = [Patch(color=OBSTACLE_COLOR, alpha=OBSTACLE_ALPHA, label="obstacles")]
    handles += [
        Patch(color=STATE_COLORS[i % len(STATE_COLORS)], label=lab) for i, lab in enumerate(labels)
    ]
    points = [faces.reshape(-1, 3)]
    if path is not None and len(path) > 1:
        dense = _along(path, max(64, 8 * len(path)))
        tip = np.asarray(_tip_kernel(robot)(np.asarray(dense, np.float32)), np.float64)
        ax.plot(tip[:, 0], tip[:, 1], tip[:, 2], color=PATH_COLOR, lw=1.6, zorder=10)
        points.append(tip)
        handles.append(
            Line2D(
                [], [], color=PATH_COLOR, lw=1.6, label=f"path: hand trace, {len(ghosts)} states"
            )
        )
    if mark_collisions and touching.any():
        handles.append(Patch(color=COLLISION_COLOR, label="sphere touching an obstacle"))
    if log is not None:
        log(
            f"draw_scene {getattr(env, 'name', '')}: {len(faces):,} faces; spheres touching "
            f"an obstacle: {touching[len(ghosts) :].tolist()} in the {len(states)} states, "
            f"{touching[: len(ghosts)].tolist()} in the {len(ghosts)} path states"
        )

    _finish_axes(
        ax,
        np.concatenate(points) if box is None else box,
        auto_view(world) if view is None else view,
        getattr(env, "name", "") if title is None else title,
        handles if legend else None,
    )
    return fig


def _arm_faces(
    env,
    drawn: np.ndarray,
    n_ghosts: int,
    arm_quads: np.ndarray,
    mark_collisions: bool,
    quads: list,
    colors: list,
    bar,
) -> np.ndarray:
    """Appends the arm's sphere faces at each ``drawn`` state (the first ``n_ghosts`` faded
    path states, then the states in their colours) to ``quads`` and their colours to
    ``colors``; returns the number of spheres touching an obstacle per drawn state."""
    from matplotlib.colors import to_rgba

    touching = np.zeros(len(drawn), int)
    if not len(drawn):
        return touching
    centres, clear = _arm_kernel(env.robot)(
        np.asarray(drawn, np.float32), env.world, float(env.padding)
    )
    centres, clear = np.asarray(centres, np.float64), np.asarray(clear)
    for i in range(len(drawn)):
        if i < n_ghosts:  # fades in towards the goal
            base = to_rgba(PATH_COLOR, 0.12 + 0.23 * (i + 1) / (n_ghosts + 1))
        else:
            base = to_rgba(STATE_COLORS[(i - n_ghosts) % len(STATE_COLORS)], 0.9)
        q = (arm_quads + centres[i][:, None, None, :]).reshape(-1, 4, 3)
        rgba = np.tile(base, (arm_quads.shape[0], arm_quads.shape[1], 1))
        if mark_collisions:
            hit = clear[i] <= 0
            touching[i] = int(hit.sum())
            rgba[hit] = to_rgba(COLLISION_COLOR, max(base[3], 0.6))
        quads.append(q)
        colors.append(rgba.reshape(-1, 4))
        bar.update(1)
    return touching


def _drawn_states(env, d: int, states, path, labels, path_states: int):
    """``(states, labels, path, ghosts)`` of :func:`draw_scene` from its arguments: the
    states (default: the path's ends, else ``env.query``), one label each, the checked
    path and the ``path_states - 2`` faded states spread along it."""
    default_labels = None
    if states is None:
        if path is not None:
            p = _states(path, d, "path")
            states, default_labels = p[[0, -1]], ["start", "goal"]
        elif getattr(env, "query", None) is not None:
            states, default_labels = np.asarray(env.query, np.float64), ["start", "goal"]
        else:
            states = np.zeros((0, d))
    states = np.zeros((0, d)) if np.asarray(states).size == 0 else _states(states, d, "states")
    if labels is None:
        labels = default_labels or [f"state {i}" for i in range(len(states))]
    if len(labels) != len(states):
        raise ValueError(f"labels: {len(labels)} for {len(states)} states")
    path = None if path is None else _states(path, d, "path")
    ghosts = np.zeros((0, d))
    if path is not None and len(path) > 1 and path_states > 2:
        ghosts = _along(path, path_states)[1:-1]
    return states, labels, path, ghosts


def _finish_axes(ax, points: np.ndarray, view: tuple[float, float], title: str, handles):
    """Equal metric axes around ``points``, the view ``(elevation, azimuth)``, labels in
    metres, the title and (unless ``handles`` is None) the legend."""
    _equal_axes(ax, points)
    ax.view_init(elev=view[0], azim=view[1])
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.zaxis.set_rotate_label(False)  # else it reads "(m) z" from some views
    ax.set_zlabel("z (m)", rotation=90)
    ax.set_title(title)
    if handles is not None:
        ax.legend(handles=handles, loc="upper left", fontsize=8, framealpha=0.85)


def _limits(limits, world) -> np.ndarray:
    """``(2, 3)`` corners of ``limits`` (``"bounds"``: the world's)."""
    bounds = isinstance(limits, str) and limits == "bounds"
    try:
        box = np.asarray(world.bounds if bounds else limits, np.float64)
    except (TypeError, ValueError):
        box = np.zeros(0)
    if box.shape != (3, 2) or not np.all(np.isfinite(box)) or np.any(box[:, 1] < box[:, 0]):
        raise ValueError(
            "limits must be None, 'bounds' or [[xmin, xmax], [ymin, ymax], "
            f"[zmin, zmax]], got {limits!r}"
        )
    return box.T


def _equal_axes(ax, points: np.ndarray) -> None:
    """Limits around ``points`` with the same length per unit on every axis."""
    if not len(points):
        points = np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])
    lo, hi = points.min(axis=0), points.max(axis=0)
    mid, half = (lo + hi) / 2, max(float((hi - lo).max()) / 2, 1e-3) * 1.02
    ax.set_xlim(mid[0] - half, mid[0] + half)
    ax.set_ylim(mid[1] - half, mid[1] + half)
    ax.set_zlim(mid[2] - half, mid[2] + half)
    ax.set_box_aspect((1, 1, 1))


def save(fig, path: str | Path, dpi: int = 110, close: bool = True) -> Path:
    """Writes ``fig`` to ``path`` atomically (the format from the suffix, e.g. ``.png``),
    tightly cropped, and closes it unless ``close=False``; returns the path."""
    out = artifacts.save_figure(fig, path, dpi=dpi, bbox_inches="tight")
    if close:
        _plt().close(fig)
    return Path(out)
