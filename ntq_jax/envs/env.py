"""Environments: a robot in a world of obstacles, with a data-generation padding.

``make_env("point/0")`` builds a preset (see :mod:`ntq_jax.presets`);
``make_env("my_map.json")`` loads a user's map in this JSON format::

    {"name": "my_map",
     "robot": {"kind": "point" | "rigid_body" | "nlink", ...robot parameters},
     "bounds": [[xmin, xmax], [ymin, ymax]],
     "boxes": [[cx, cy, half_w, half_h], ...],
     "discs": [[cx, cy, r], ...],
     "padding": 0.8}

Parsing is strict (:mod:`ntq_jax.validation`): every row has exactly its
width, every entry is a finite number (``true`` and ``"22"`` are not), and
every problem is one :class:`EnvError` line naming the key, the row and the
expected form. A discretised robot's ``resolution`` is bounded below by
:func:`check_resolution` (at most :data:`MAX_STATES_PER_MOTION` states per motion).

A user's occupancy grid (:mod:`ntq_jax.grid_maps`: a ROS ``map_server`` YAML
or a MovingAI ``.map``) loads with ``make_env("office.yaml", robot=...,
padding=...)`` or through a small JSON that names it::

    {"name": "office", "grid": "office.yaml", "robot": {"kind": "point"},
     "padding": 0.1, "unknown": "occupied", "scale": 1.0}

(``grid`` relative to the JSON file; ``unknown``: ROS maps only, what unknown
cells become; ``scale``: MovingAI only, world units per cell). Its occupied
cells become boxes (:func:`ntq_jax.grid_maps.rectangle_cover`, exact), its
extent the bounds; ``Env.grid`` keeps the grid (grid A* plans on it). A world
with more than :data:`ntq_jax.broadphase.UNROLL_MAX` boxes gets a broad-phase
index (:func:`index_reach`), which makes the kernels scale with the obstacle
count and changes no answer.

Every method that touches geometry takes ``padding=``: ``None`` (default) is
the environment's own padding, the data-generation geometry of the paper;
``padding=0`` is the evaluation geometry.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ntq_jax import artifacts, broadphase, geometry, grid_maps, validation
from ntq_jax import gamma as G
from ntq_jax import queries as Q
from ntq_jax.batching import bucket_size
from ntq_jax.geometry import World, World3D
from ntq_jax.robots import Robot, robot_from_json
from ntq_jax.robots import batch as _batch
from ntq_jax.robots.batch import distance_batch, is_valid_batch, steer_to_batch
from ntq_jax.robots.rows import MIN_BUCKET, host_rows

Array = jax.Array

_JSON_KEYS = {"name", "robot", "bounds", "boxes", "discs", "padding"}
_JSON3D_KEYS = {"name", "robot", "bounds", "spheres", "cuboids", "capsules", "padding", "query"}
WORLD3D_KEYS = ("bounds", "spheres", "cuboids", "capsules")
#: ``make_env("panda/<scene>/<number>")``: MotionBenchMaker's problem with the Panda.
PANDA_PREFIX = "panda/"
_GRID_JSON_KEYS = {"name", "grid", "robot", "padding", "unknown", "scale"}


#: The most states a discretised ``steer_to`` may check on one motion between two valid
#: states: ``resolution`` must be at least the robot's longest motion divided by this
#: (:func:`check_resolution`). With 10^5, one motion takes milliseconds; the presets
#: check at most a few hundred states per motion.
MAX_STATES_PER_MOTION = 100_000


class EnvError(ValueError):
    """A bad environment name or file."""


def check_resolution(robot: Robot, world: World) -> None:
    """Refuses a ``resolution`` so fine that one motion would check too many states.

    For the robots with a discretised ``steer_to`` (they have ``resolution`` and
    ``longest_motion``): ``resolution >= longest_motion(world) / MAX_STATES_PER_MOTION``,
    with the longest motion between two valid states in the robot's cost metric
    (rigid body: the workspace diagonal plus ``angle_weight * pi``; arm: the joint
    box diagonal ``2 pi sqrt(n)`` radians). The point robot's check is exact and
    has no resolution.

    Raises:
        ValueError: naming the resolution, the bound and how it was derived.
    """
    longest = getattr(robot, "longest_motion", None)
    if longest is None:
        return
    length = float(longest(world))
    floor = length / MAX_STATES_PER_MOTION
    if not robot.resolution >= floor:
        unit = " rad" if robot.kind == "nlink" else ""
        raise ValueError(
            f"{robot.kind}.resolution {robot.resolution:g}{unit} is too fine: the longest motion "
            f"({length:.4g}{unit}) would be checked at {length / robot.resolution:.3g} states; "
            f"use resolution >= {floor:.3g}{unit} (at most {MAX_STATES_PER_MOTION} states per motion)"
        )


def index_reach(robot: Robot, world: World, padding: float) -> tuple[float, float]:
    """``(reach, cell)`` of the broad-phase index ``Env`` gives a world with many boxes.

    ``cell`` from the box density (:func:`ntq_jax.broadphase.choose_cell`);
    ``reach = padding + rho + cell / 2`` with ``rho`` the robot's footprint radius
    (the rigid body's half diagonal, 0 for the point and the arm's links): every
    check at the environment's padding or less uses the index, and segments are
    covered by cells about one cell apart.
    """
    rho = float(getattr(robot, "half_diagonal", 0.0))
    cell = broadphase.choose_cell(np.asarray(world.bounds), world.num_boxes)
    return float(padding) + rho + 0.5 * cell, cell


@dataclasses.dataclass(frozen=True, eq=False)
class Env:
    """A planning environment.

    Attributes:
        name: preset name (``"point/0"``) or the JSON ``name``.
        robot: the robot description (static, hashable).
        world: workspace bounds and obstacles (a pytree of arrays).
        padding: clearance used for data generation (``>= 0``).
        grid: the :class:`ntq_jax.grid_maps.OccupancyGrid` the world was imported
            from, or None (grid A* plans on it at its own resolution).
        query: ``(2, d)`` float32 start and goal that come with the environment (a
            MotionBenchMaker problem's, or a 3-D JSON's ``"query"``), or None. Not part
            of :meth:`content_hash` (it is a problem posed in the world, not the world).
    """

    name: str
    robot: Robot
    world: World | World3D
    padding: float
    grid: grid_maps.OccupancyGrid | None = None
    query: np.ndarray | None = None

    def __post_init__(self):
        try:
            check_resolution(self.robot, self.world)
        except ValueError as e:
            raise EnvError(f"{self.name}: {e}") from None
        if (
            isinstance(self.world, World)
            and self.world.num_boxes > broadphase.UNROLL_MAX
            and self.world.index is None
        ):
            reach, cell = index_reach(self.robot, self.world, self.padding)
            object.__setattr__(self, "world", broadphase.with_index(self.world, reach, cell))

    def content_hash(self) -> str:
        """sha256 (hex) of what the environment is, not what it is called: the robot's
        parameters, the padding and the exact float32 bounds, boxes and discs. Two maps
        with the same content have the same hash whatever their names or file paths."""
        keys = ("bounds", "boxes", "discs") if isinstance(self.world, World) else WORLD3D_KEYS
        content = {
            "robot": self.robot.to_json(),
            "padding": float(self.padding),
            **{k: np.asarray(getattr(self.world, k), np.float64).tolist() for k in keys},
        }
        return artifacts.sha256_json(content)

    # -- geometry -----------------------------------------------------------
    @property
    def dim(self) -> int:
        return self.robot.dim

    def resolve_padding(self, padding: float | None) -> float:
        """``padding`` as a number: None is the environment's own (data-generation) padding."""
        return self.padding if padding is None else validation.check_padding(padding)

    def _rows(self, x, what: str):
        """``x`` validated as ``(N, d)`` rows of real numbers: a float32 host NumPy array
        (:func:`ntq_jax.robots.rows.host_rows`: the caller's own memory where it can be),
        or a float32 JAX array when ``x`` is traced or lives on another device."""
        if not isinstance(x, (jax.Array, np.ndarray)):
            try:
                x = np.asarray(x)
            except (TypeError, ValueError) as e:
                raise TypeError(
                    f"{what} must be an (N, {self.dim}) array of real numbers, "
                    f"got {type(x).__name__} ({e})"
                ) from None
        if np.dtype(x.dtype).kind not in "fiu":  # not bool, complex, strings, objects
            raise TypeError(
                f"{what} must be an (N, {self.dim}) array of real numbers, got "
                f"dtype {np.dtype(x.dtype)}"
            )
        if x.ndim != 2 or x.shape[1] != self.dim:
            raise ValueError(
                f"{what} must have shape (N, {self.dim}) for {self.name} "
                f"({self.robot.kind}), got {tuple(x.shape)}"
            )
        rows = host_rows(x)
        return jnp.asarray(x, jnp.float32) if rows is None else rows

    def _pairs(self, a, b):
        a, b = self._rows(a, "a"), self._rows(b, "b")
        if a.shape != b.shape:
            raise ValueError(f"a and b must have the same shape, got {a.shape} and {b.shape}")
        return a, b

    def is_valid(self, states, padding: float | None = None) -> Array:
        """``(N, d) -> (N,)`` bool: in bounds and clear of obstacles (False for NaN/inf).

        ``states`` may be a JAX array, a NumPy array or a nested list; the answer is
        a JAX array. Batches of every size run at the kernel's speed in pieces of a
        few compiled sizes (:mod:`ntq_jax.robots.rows`), read in place: a CPU JAX
        array or a float32 C-contiguous NumPy array is not copied (other dtypes and
        layouts are converted to float32, rounding to nearest, first). For NumPy
        input the call returns once the answer is computed, so the array may be
        modified afterwards. Inside ``jax.jit`` the kernel runs on the traced batch.
        """
        p = self.resolve_padding(padding)
        x = self._rows(states, "states")
        if isinstance(x, jax.Array):
            if isinstance(x, jax.core.Tracer):
                return _batch.is_valid_cm(self.robot, self.world, x.T, p)
            return is_valid_batch(self.robot, self.world, _direct_rows(x), p)[: x.shape[0]]
        return _settled(states, x, _batch.valid_rows(self.robot, self.world, x, p, _whole(states)))

    def steer_to(self, a, b, padding: float | None = None, check: str = "discretized") -> Array:
        """``(N, d), (N, d) -> (N,)`` bool: True where the straight connection is collision-free.

        ``check``: ``"discretized"`` (default; the paper's check: states at most
        the robot's ``resolution`` apart, exact for the point robot) or
        ``"certified"`` (True only when every configuration of the motion is
        proven clear; see :mod:`ntq_jax.robots.certified`).

        ``a`` and ``b`` may be JAX arrays, NumPy arrays or nested lists; the
        answer is a JAX array in every case. Batches of every size run at the
        kernel's speed: the rows reach the compiled check in pieces of a few
        power-of-two sizes, read in place (:mod:`ntq_jax.robots.rows`; the
        certified check, costly to compile, in pieces of two sizes only:
        :data:`~ntq_jax.robots.batch.CERTIFIED_PIECE` and
        :data:`~ntq_jax.robots.batch.CERTIFIED_CHUNK` rows, the shape
        :func:`~ntq_jax.robots.batch.steer_to_pairs` uses too). A CPU JAX array
        or a float32 C-contiguous NumPy array is not copied; other dtypes and
        layouts are converted to float32 (round to nearest) first. For NumPy
        input the call returns once the answer is computed, so the arrays may be
        modified afterwards. Inside ``jax.jit`` the check runs on the traced batch.
        """
        p = self.resolve_padding(padding)
        _batch.motion_check(self.robot, check)  # an unknown check fails here
        ra, rb = self._pairs(a, b)
        if isinstance(ra, jax.Array) or isinstance(rb, jax.Array):
            ra, rb = jnp.asarray(ra), jnp.asarray(rb)
            if isinstance(ra, jax.core.Tracer) or isinstance(rb, jax.core.Tracer):
                return _batch.steer_to_cm(self.robot, self.world, ra.T, rb.T, p, check=check)
            return steer_to_batch(
                self.robot, self.world, _direct_rows(ra), _direct_rows(rb), p, check
            )[: ra.shape[0]]
        out = _batch.steer_rows(self.robot, self.world, ra, rb, p, check, _whole(a, b))
        return _settled((a, b), (ra, rb), out)

    def distance(self, a, b) -> Array:
        """``(N, d), (N, d) -> (N,)``: the robot's cost metric.

        Input as for :meth:`steer_to` (large arrays are read in place).
        """
        ra, rb = self._pairs(a, b)
        if isinstance(ra, jax.Array) or isinstance(rb, jax.Array):
            ra, rb = jnp.asarray(ra), jnp.asarray(rb)
            if isinstance(ra, jax.core.Tracer) or isinstance(rb, jax.core.Tracer):
                return jax.vmap(self.robot.distance)(ra, rb)
            return distance_batch(self.robot, _direct_rows(ra), _direct_rows(rb))[: ra.shape[0]]
        return _settled((a, b), (ra, rb), _batch.distance_rows(self.robot, ra, rb, _whole(a, b)))

    def rasterize(self, resolution: float, padding: float | None = None) -> np.ndarray:
        """Occupancy grid ``(H, W)`` bool of the workspace (point robot geometry; planar
        worlds only)."""
        if not isinstance(self.world, World):
            raise EnvError(f"{self.name}: rasterize is for planar worlds; this one is 3-D")
        return geometry.rasterize(self.world, resolution, self.resolve_padding(padding))

    # -- sampling ------------------------------------------------------------
    def sample_states(self, key: Array, n: int, padding: float | None = None) -> np.ndarray:
        """``n`` uniform valid states ``(n, d)``."""
        return Q.sample_states(self.robot, self.world, key, n, self.resolve_padding(padding))

    def sample_queries(
        self,
        key: Array,
        n: int,
        p_nt: float = 0.0,
        padding: float | None = None,
        n_max: int = Q.DEFAULT_N_MAX,
    ):
        """``n`` queries of Alg. 2 ``((n, 2, d), kind (n,) int8)``; see :mod:`ntq_jax.queries`."""
        return Q.sample_queries(
            self.robot, self.world, key, n, p_nt, self.resolve_padding(padding), n_max
        )

    def gamma_nt(
        self,
        key: Array,
        n: int,
        padding: float | None = None,
        chunk: int | None = None,
        progress=None,
    ) -> G.GammaEstimate:
        """gamma_nt over ``n`` uniform queries, with its Wilson 95% interval."""
        return G.gamma_nt(
            self.robot, self.world, key, n, self.resolve_padding(padding), chunk, progress
        )

    # -- JSON ------------------------------------------------------------------
    def to_json(self) -> dict[str, Any]:
        """The environment in the JSON format of this module's docstring (a dict)."""
        if isinstance(self.world, World3D):
            out = {
                "name": self.name,
                "robot": self.robot.to_json(),
                **self.world.to_json(),
                "padding": self.padding,
            }
            if self.query is not None:
                out["query"] = np.asarray(self.query, np.float64).tolist()
            return out
        return {
            "name": self.name,
            "robot": self.robot.to_json(),
            "bounds": np.asarray(self.world.bounds, np.float64).round(6).tolist(),
            "boxes": np.asarray(self.world.boxes, np.float64).round(6).tolist(),
            "discs": np.asarray(self.world.discs, np.float64).round(6).tolist(),
            "padding": self.padding,
        }

    def save_json(self, path: str | os.PathLike) -> Path:
        """Writes :meth:`to_json` atomically (temporary file, then rename)."""
        return artifacts.write_json(path, self.to_json())

    @staticmethod
    def from_grid(
        path: str | os.PathLike,
        robot: dict | Robot | None = None,
        padding: float = 0.0,
        name: str | None = None,
        unknown: str = "occupied",
        scale: float | None = None,
        where: str | None = None,
    ) -> "Env":
        """An environment from a grid map file (ROS ``.yaml`` or MovingAI ``.map``).

        ``robot``: a robot JSON dict or a Robot (default the point robot);
        ``name`` defaults to the file's stem. See :mod:`ntq_jax.grid_maps`.

        Raises:
            EnvError: one line naming the file and the line or field.
        """
        where = where or f"environment file {str(path)!r}"
        try:
            grid = grid_maps.read_grid(path, unknown=unknown, scale=scale)
        except grid_maps.GridMapError as e:
            raise EnvError(str(e)) from None
        if robot is None:
            robot = {"kind": "point"}
        if isinstance(robot, dict):
            try:
                robot = robot_from_json(robot, where=f"{where}: robot")
            except (TypeError, ValueError) as e:
                raise EnvError(str(e)) from None
        try:
            world = grid_maps.grid_world(grid)
        except grid_maps.GridMapError as e:
            raise EnvError(str(e)) from None
        try:
            padding = validation.number(padding, "padding", minimum=0)
            check_resolution(robot, world)
        except (TypeError, ValueError) as e:
            raise EnvError(f"{where}: {e}") from None
        return Env(name or Path(path).stem, robot, world, padding, grid)

    @staticmethod
    def from_json(
        spec: dict[str, Any], where: str = "environment", base_dir: str | os.PathLike | None = None
    ) -> "Env":
        """Builds an Env from a JSON dict; every problem is one :class:`EnvError` naming the key.

        Strict (see the module docstring): exact row widths, finite numbers only
        (no bools, no strings, nothing reshaped), ``null`` refused, and a bounded
        ``resolution`` (:func:`check_resolution`).
        """
        if not isinstance(spec, dict):
            raise EnvError(f"{where}: expected a JSON object, got {type(spec).__name__}")
        if "grid" in spec:
            return Env._from_grid_json(spec, where, base_dir)
        if _is_3d(spec):
            return Env._from_json_3d(spec, where)
        name, robot = _name_and_robot(spec, where, _JSON_KEYS, "allowed")
        try:
            validation.check_float32({k: spec.get(k, []) for k in ("bounds", "boxes", "discs")})
            world = World.create(spec["bounds"], spec.get("boxes", []), spec.get("discs", []))
            padding = validation.number(spec.get("padding", 0.0), "padding", minimum=0)
            check_resolution(robot, world)
        except (TypeError, ValueError) as e:
            raise EnvError(f"{where}: {e}") from None
        return Env(name, robot, world, padding)

    @staticmethod
    def _from_json_3d(spec: dict[str, Any], where: str) -> "Env":
        """The 3-D form (see the module docstring)."""
        name, robot = _name_and_robot(spec, where, _JSON3D_KEYS, "a 3-D environment allows")
        if robot.kind != "serial_arm":
            raise EnvError(
                f"{where}: a 3-D world (spheres, cuboids, capsules, 3 bounds rows) "
                f"needs a 3-D robot (kind 'serial_arm'), got {robot.kind!r}"
            )
        try:
            validation.check_float32({k: spec[k] for k in WORLD3D_KEYS if k in spec})
            world = World3D.from_json({k: spec[k] for k in WORLD3D_KEYS if k in spec})
            padding = validation.number(spec.get("padding", 0.0), "padding", minimum=0)
            query = None
            if spec.get("query") is not None:
                query = validation.number_rows(spec["query"], "query", robot.dim, "[q_1, ..., q_d]")
                if query.shape[0] != 2:
                    raise ValueError(f"query must be two rows [start, goal], got {query.shape[0]}")
                query = np.asarray(query, np.float32)
        except (TypeError, ValueError) as e:
            raise EnvError(f"{where}: {e}") from None
        return Env(name, robot, world, padding, query=query)

    @staticmethod
    def _from_grid_json(spec: dict[str, Any], where: str, base_dir) -> "Env":
        """The ``{"grid": ...}`` form (see the module docstring)."""
        unknown = sorted(set(spec) - _GRID_JSON_KEYS)
        if unknown:
            raise EnvError(
                f"{where}: unknown key(s) {unknown}; a grid map JSON allows "
                f"{sorted(_GRID_JSON_KEYS)}"
            )
        grid = spec["grid"]
        if not isinstance(grid, str) or not grid:
            raise EnvError(
                f"{where}: grid must be the path of a ROS .yaml or MovingAI .map file, "
                f"got {validation.short_repr(grid)}"
            )
        path = Path(grid)
        if not path.is_absolute() and base_dir is not None:
            path = Path(base_dir) / path
        name = spec.get("name", path.stem)
        if not isinstance(name, str) or not name:
            raise EnvError(
                f"{where}: name must be a non-empty string, got {validation.short_repr(name)}"
            )
        policy = spec.get("unknown", "occupied")
        if policy not in grid_maps.UNKNOWN_POLICIES:
            raise EnvError(
                f"{where}: unknown must be one of {list(grid_maps.UNKNOWN_POLICIES)}, "
                f"got {validation.short_repr(policy)}"
            )
        if "unknown" in spec and path.suffix.lower() == ".map":
            raise EnvError(
                f"{where}: 'unknown' is for ROS maps; a MovingAI map has no unknown cells"
            )
        if "robot" not in spec:
            raise EnvError(f"{where}: missing required key 'robot'")
        return Env.from_grid(
            path,
            spec["robot"],
            spec.get("padding", 0.0),
            name,
            policy,
            spec.get("scale"),
            where=where,
        )


#: The smallest compiled batch size: smaller batches are padded to it
#: (:data:`ntq_jax.robots.rows.MIN_BUCKET`).
BUCKET_MIN_ROWS = MIN_BUCKET


def _name_and_robot(spec: dict, where: str, keys: set, allowed: str) -> tuple[str, Robot]:
    """The keys checked against ``keys`` (``allowed``: how the error names them), and the
    ``name`` and ``robot`` of an environment JSON; one :class:`EnvError` line otherwise."""
    unknown = sorted(set(spec) - keys)
    if unknown:
        raise EnvError(f"{where}: unknown key(s) {unknown}; {allowed}: {sorted(keys)}")
    for key in ("robot", "bounds"):
        if key not in spec:
            raise EnvError(f"{where}: missing required key {key!r}")
    name = spec.get("name", "custom")
    if not isinstance(name, str) or not name:
        raise EnvError(
            f"{where}: name must be a non-empty string, got {validation.short_repr(name)}"
        )
    try:
        return name, robot_from_json(spec["robot"], where=f"{where}: robot")
    except (TypeError, ValueError) as e:
        raise EnvError(str(e)) from None


def _is_3d(spec: dict) -> bool:
    """Whether an environment JSON is the 3-D form: 3-D obstacles, or three bounds rows."""
    if any(k in spec for k in ("spheres", "cuboids", "capsules")):
        return True
    bounds = spec.get("bounds")
    return isinstance(bounds, (list, tuple)) and len(bounds) == 3


def _direct_rows(x: Array) -> Array:
    """A concrete batch on another device than the CPU, padded (zeros) to a power of two of
    at least 64 rows for the kernel, so varying sizes share a handful of programs (the
    per-row answers of the first rows are those of ``x`` alone)."""
    n = x.shape[0]
    m = bucket_size(n, BUCKET_MIN_ROWS)
    return x if m == n else jnp.pad(x, ((0, m - n), (0, 0)))


def _whole(*given) -> tuple | None:
    """The inputs themselves when all are float32 JAX arrays (the kernels take them as they
    are when a batch needs no splitting), else None."""
    if all(isinstance(g, jax.Array) and g.dtype == jnp.float32 for g in given):
        return given
    return None


def _settled(given, rows, out: Array) -> Array:
    """``out``, waited for when it reads a caller's NumPy array in place (which may change
    once the call returns); answers computed from private copies or immutable JAX arrays
    are returned at once."""
    given = given if isinstance(given, tuple) else (given,)
    rows = rows if isinstance(rows, tuple) else (rows,)
    if any(isinstance(g, np.ndarray) and r is g for g, r in zip(given, rows)):
        return out.block_until_ready()
    return out
