"""VAMP's RRT-Connect on the Panda's problems: :func:`plan_vamp`, the ``"vamp"`` planner (when ``import vamp`` works).

VAMP (Thomason, Kingston and Kavraki, "Motions in Microseconds via Vectorized
Sampling-Based Planning", ICRA 2024; https://github.com/KavrakiLab/vamp) checks the
Panda's collision spheres with SIMD instructions and plans MotionBenchMaker's problems
in about a millisecond. This adapter plans an :class:`ntq_jax.Env` with the Panda
(``make_env("panda/<scene>/<number>")``, padding 0) with VAMP's RRT-Connect (range
1 rad, ``vamp.configure_robot_and_planner_with_kwargs("panda", "rrtc")``) and VAMP's
simplification, then verifies every path with the package's own check
(:func:`ntq_jax.planners.verify.finalize`, discretised or certified): VAMP's
geometry is its own (its spheres are the ones the package's Panda preset was read
from, its environment is built here from the same :class:`~ntq_jax.geometry.World3D`),
so a path it returns is SOLVED only if the package's check agrees.

The world maps one to one: spheres ``vamp.Sphere(centre, r)``; cuboids
``vamp.Cuboid(centre, euler_xyz, half_extents)`` with the rotation's XYZ Euler angles
(:func:`cuboid_euler_xyz`, VAMP's ``Rz Ry Rx`` convention); capsules
``vamp.Cylinder(centre, euler_xyz, r, length)`` (:func:`capsule_center_form`) added
with ``add_capsule`` (VAMP's own MotionBenchMaker
loader reads the scene ``box``'s cylinders as cuboids; the package's loader does the
same, so those arrive here as cuboids already).

Building VAMP (it is not in CI: its build fetches sources from GitHub)
----------------------------------------------------------------------
``pip install vamp-planner`` builds from the sdist (scikit-build-core, nanobind,
CMake >= 3.16, a C++17 compiler; the Python ABI ``cp312`` stable wheel tag, Python
>= 3.8). The build needs:

* Eigen 3.4 (``find_package(Eigen3)``): ``sudo apt install libeigen3-dev`` (Debian,
  Ubuntu), ``brew install eigen`` or ``conda install -c conda-forge eigen``;
* access to GitHub during the build: CMake downloads CPM.cmake
  (``github.com/cpm-cmake/CPM.cmake``) and CPM fetches nanobind, nigh, pdqsort and
  (x86-64) SIMDxorshift from GitHub;
* x86-64 with AVX2 (it compiles with ``-march=native -mavx2``) or ARM64 with NEON, so
  build on the machine that runs it (the wheel is not portable across CPUs).

On a developer machine::

    sudo apt install libeigen3-dev          # or the brew / conda package
    pip install vamp-planner                # ~2-5 min of C++ compilation
    python -c "import vamp; print(vamp.robots)"
    taskset -c 0 python benchmarks/bench_panda_plan.py vamp

Without GitHub at build time (done on the 2-core benchmark machine, vamp-planner
0.6.4): the sdist from the package registry, and local copies of the sources CPM
would fetch (CPM.cmake v0.40.1, nanobind at the sdist's pinned commit with its
``ext/robin_map``, nigh, pdqsort, SIMDxorshift) and of Eigen 3.4 (installed with
CMake into a prefix). In the unpacked sdist, ``cmake/FetchInitCPM.cmake`` becomes
``set(CPM_USE_LOCAL_PACKAGES ON)`` plus ``include(<copy>/CPM.cmake)`` (the download
removed), ``pyproject.toml``'s ``VAMP_ROBOT_MODULES`` / ``VAMP_ROBOT_STRUCTS`` may be
cut to ``sphere;panda`` / ``Sphere;Panda`` (a shorter build), and::

    export CMAKE_ARGS="-DEigen3_DIR=<prefix>/share/eigen3/cmake \
      -DCPM_nanobind_SOURCE=<nanobind> -DCPM_nigh_SOURCE=<nigh> \
      -DCPM_pdqsort_SOURCE=<pdqsort> -DCPM_SIMDxorshift_SOURCE=<SIMDxorshift>"
    pip install scikit-build-core nanobind && pip install <sdist folder> --no-build-isolation

(about 3 minutes here). Two things found in 0.6.4's Python bindings: the
``Cylinder(endpoint, endpoint, radius)`` constructor assigns to unconstructed memory and
crashes the process, so :func:`vamp_environment` builds capsules from the centre form
(:func:`capsule_center_form`); and ``vamp.<robot>.validate_motion`` checks at
resolution 1 (one rake of states per radian), not the robot's 32 that VAMP's planners
use, so it is not VAMP's motion check (``benchmarks/bench_panda.py vamp`` times that
one in C++, ``benchmarks/vamp_harness.cpp``).
"""

from __future__ import annotations

import math
import time

import numpy as np

from ntq_jax.planners.options import bool_option, motion_check_option
from ntq_jax.planners.verify import finalize, valid_queries
from ntq_jax.types import PlanResult, PlanStatus

__all__ = [
    "plan_vamp",
    "require_vamp",
    "vamp_environment",
    "cuboid_euler_xyz",
    "capsule_center_form",
    "BUILD_HINT",
]

BUILD_HINT = (
    "VAMP is not importable: build it with `pip install vamp-planner` (needs Eigen 3, "
    "a C++17 compiler and GitHub access at build time; see "
    "ntq_jax/planners/vamp_bridge.py)"
)


def require_vamp():
    """The ``vamp`` module, or ImportError naming :data:`BUILD_HINT`."""
    try:
        import vamp
    except ImportError as e:
        raise ImportError(f"{BUILD_HINT} ({e})") from None
    return vamp


def cuboid_euler_xyz(rotation) -> tuple[float, float, float]:
    """The angles ``(rx, ry, rz)`` with ``Rz(rz) Ry(ry) Rx(rx) == rotation`` (VAMP's cuboid
    convention: ``euler_xyz`` applied about x, then y, then z, fixed axes).

    ``rotation``: ``(3, 3)`` orthonormal, the box's axes as columns (the
    :class:`~ntq_jax.geometry.World3D` cuboid row's ``R``). At ``ry = +-pi/2`` (gimbal
    lock) ``rx`` is 0 and ``rz`` carries the rest.
    """
    r = np.asarray(rotation, np.float64).reshape(3, 3)
    ry = math.asin(max(-1.0, min(1.0, -r[2, 0])))
    if math.cos(ry) > 1e-9:
        rx = math.atan2(r[2, 1], r[2, 2])
        rz = math.atan2(r[1, 0], r[0, 0])
    else:
        rx = 0.0
        rz = math.atan2(-r[0, 1], r[1, 1])
    return rx, ry, rz


def capsule_center_form(a, b) -> tuple[list[float], list[float], float]:
    """``(center, euler_xyz, length)`` of the segment ``a -> b`` for VAMP's
    ``Cylinder(center, euler_xyz, radius, length)``, whose ends are ``center +-
    length / 2 * R e_z`` with ``R = Rz Ry Rx`` (``euler_xyz`` = ``(rx, ry, 0)`` here:
    ``R e_z = (cos rx sin ry, -sin rx, cos rx cos ry)``, the segment's direction).

    The capsules go in by this form because VAMP 0.6.4's constructor from two ends
    assigns to unconstructed memory and crashes the process."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    d = b - a
    length = float(np.linalg.norm(d))
    u = d / length if length > 0 else np.array([0.0, 0.0, 1.0])
    rx = -math.asin(max(-1.0, min(1.0, float(u[1]))))
    ry = math.atan2(float(u[0]), float(u[2]))
    return ((a + b) / 2).tolist(), [rx, ry, 0.0], length


def vamp_environment(world, vamp=None):
    """A ``vamp.Environment`` holding the obstacles of a :class:`~ntq_jax.geometry.World3D`."""
    vamp = vamp or require_vamp()
    venv = vamp.Environment()
    for x, y, z, r in np.asarray(world.spheres, np.float64):
        venv.add_sphere(vamp.Sphere([x, y, z], r))
    for row in np.asarray(world.cuboids, np.float64):
        venv.add_cuboid(
            vamp.Cuboid(row[:3].tolist(), list(cuboid_euler_xyz(row[6:15])), row[3:6].tolist())
        )
    for row in np.asarray(world.capsules, np.float64):
        center, euler, length = capsule_center_form(row[:3], row[3:6])
        venv.add_capsule(vamp.Cylinder(center, euler, float(row[6]), length))
    return venv


def plan_vamp(
    env,
    queries,
    *,
    padding: float | None = None,
    seed: int = 0,
    simplify: bool = True,
    check: str = "discretized",
    sampler: str = "halton",
) -> PlanResult:
    """Plans each query with VAMP's RRT-Connect (+ simplification), verified by the package.

    Args:
        env: an environment with the Panda preset (``make_env("panda/...")``).
        queries: ``(K, 2, 7)`` (start, goal) joint states.
        padding: must resolve to 0 (VAMP has no clearance margin).
        seed: the sampler skips ``seed * 1000`` samples before the first query and
            is reset before each query (so a query's path does not depend on the batch).
        simplify: VAMP's simplification (its default routine) of each path.
        check: the package's motion check of the final verification.
        sampler: VAMP's sampler (``"halton"``, VAMP's default, or ``"xorshift"``).

    Returns:
        A verified :class:`PlanResult`; ``info``: ``vamp_times`` ``(K,)`` seconds of
        VAMP's planning + simplification (its own clocks), ``iterations`` ``(K,)``,
        ``planner_costs`` (VAMP's path lengths), ``rejected`` (paths the package's
        check refused).

    Raises:
        ImportError: ``vamp`` is missing (:data:`BUILD_HINT`); ValueError: not the
        Panda, or a padding other than 0.
    """
    vamp = require_vamp()
    simplify = bool_option("vamp", "simplify", simplify)
    check = motion_check_option("vamp", check)
    if env.robot.kind != "serial_arm" or env.robot.to_json().get("preset") != "panda":
        raise ValueError(
            f"vamp: {env.name} does not have the Panda preset; VAMP plans its "
            "own compiled Panda only"
        )
    pad = env.resolve_padding(padding)
    if pad != 0.0:
        raise ValueError(f"vamp: padding must be 0 (VAMP has no clearance margin), got {pad}")
    q = np.asarray(queries, np.float32)
    nq, d = q.shape[0], q.shape[2]
    t0 = time.perf_counter()
    module, planner, settings, simp_settings = vamp.configure_robot_and_planner_with_kwargs(
        "panda", "rrtc"
    )
    venv = vamp_environment(env.world, vamp)
    rng = getattr(module, sampler)()
    status = np.full(nq, PlanStatus.NO_PATH, np.int8)
    status[~valid_queries(env, q, pad)] = PlanStatus.INVALID
    found, times = {}, np.zeros(nq)
    iters, own = np.zeros(nq, np.int64), np.full(nq, np.inf)
    for i in np.flatnonzero(status == PlanStatus.NO_PATH):
        rng.reset()
        rng.skip(int(seed) * 1000)
        result = planner(q[i, 0], q[i, 1], venv, settings, rng)
        times[i] = result.nanoseconds * 1e-9
        iters[i] = result.iterations
        if not result.solved:
            continue
        path = result.path
        if simplify:
            simple = module.simplify(path, venv, simp_settings, rng)
            times[i] += simple.nanoseconds * 1e-9
            path = simple.path
        own[i] = path.cost()
        found[int(i)] = np.asarray(path.numpy(), np.float32)
        status[i] = PlanStatus.SOLVED
    width = max([2] + [len(p) for p in found.values()])
    paths = np.full((nq, width, d), np.nan, np.float32)
    lengths = np.zeros(nq, np.int32)
    for i, p in found.items():
        paths[i, : len(p)], lengths[i] = p, len(p)
    info = {
        "planner": "vamp",
        "simplify": simplify,
        "sampler": sampler,
        "vamp_times": times,
        "iterations": iters,
        "planner_costs": own,
    }
    res = finalize(q, paths, lengths, status, info, env, pad, check)
    info["time"] = time.perf_counter() - t0
    return res
