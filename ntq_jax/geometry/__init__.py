"""Exact 2D geometry: obstacles as arrays, and distance/intersection kernels.

* :mod:`~ntq_jax.geometry.world`: :class:`World` and the kernels' compiler options;
* :mod:`~ntq_jax.geometry.shapes`: points, segments and oriented rectangles against
  boxes and discs (``*_hits_*``, ``*_free``);
* :mod:`~ntq_jax.geometry.clearance`: Euclidean distances and clearances;
* :mod:`~ntq_jax.geometry.raster`: rasterisation and grid cells;
* :mod:`~ntq_jax.geometry.world3d` and :mod:`~ntq_jax.geometry.shapes3d`: the 3-D world
  (:class:`World3D`: spheres, oriented cuboids, capsules) and its signed distances and
  ball clearances, for 3-D arms; the paragraphs below are about the 2-D kernels.

Obstacles are axis-aligned boxes ``[cx, cy, half_w, half_h]`` and discs
``[cx, cy, r]`` inside a rectangular workspace ``[[xmin, xmax], [ymin, ymax]]``.

*Padding means clearance*: a shape is in collision with an obstacle when its
Euclidean distance to the obstacle is ``<= padding``. With ``padding = 0`` this
is the closed-set intersection test (touching counts as a collision).

Every kernel here is written for ONE item (scalars or ``(2,)`` vectors) and is
batched by the caller with ``jax.vmap``. Callers batch over the minor axis of
coordinate-major ``(d, N)`` arrays (``jax.vmap(f, in_axes=1)``), which makes the
vmapped code purely elementwise over contiguous ``(N,)`` rows, the fast layout
on CPU (BENCHMARKS.md compares it with ``(N, d)`` rows).

Up to :data:`ntq_jax.broadphase.UNROLL_MAX` obstacles, the obstacle loop is
unrolled at trace time (one fused elementwise expression per obstacle), so the
number of boxes and discs is part of the compiled shape while their values are
traced: a map with the same obstacle counts never recompiles. Above it (users'
grid maps with thousands of boxes) the kernels loop over obstacle blocks, and a
world with a broad-phase index (:mod:`ntq_jax.broadphase`, ``World.index``)
tests only the boxes near the query: compile time and memory do not grow with
the obstacle count, and the answers are the same. ``padding`` is a static Python float, so the common ``padding=0``
case compiles to the cheaper closed-set test.

None of the kernels divides, so tangent and degenerate cases never produce NaN.
NaN or infinite coordinates make the ``*_free`` kernels (``point_free``,
``segment_free``, ``rect_free``) and ``in_bounds`` return False: a documented
"invalid / blocked", never an exception. The lower-level ``*_hits_*`` tests
give no guarantee for non-finite input; call them through the ``*_free``
kernels.

Every jitted batch entry point compiles with :data:`KERNEL_COMPILER_OPTIONS`
(512-bit vectors on CPUs that have them): the kernels are long chains of
elementwise compares, which wider vectors speed up (BENCHMARKS.md).
"""

from ntq_jax.geometry.clearance import (
    pose_box_dist2,
    pose_disc_dist,
    rect_box_dist2,
    rect_clearance,
    rect_disc_dist,
    segment_box_dist2,
    segment_clearance,
    segment_disc_dist,
    wall_clearance,
)
from ntq_jax.geometry.raster import cell_centers, point_to_cell, rasterize
from ntq_jax.geometry.shapes import (
    RectPose,
    in_bounds,
    point_free,
    point_hits_box,
    point_hits_disc,
    pose_hits_box,
    pose_hits_disc,
    rect_corners,
    rect_free,
    rect_hits_box,
    rect_hits_disc,
    rect_pose,
    segment_cover_steps,
    segment_free,
    segment_free_indexed,
    segment_hits_box,
    segment_hits_disc,
    segment_hits_near,
    sincos,
)
from ntq_jax.geometry.shapes3d import (
    NO_OBSTACLE_CLEARANCE,
    point_capsule_dist,
    point_cuboid_dist,
    point_sphere_dist,
    sphere_clearance,
    spheres_clear,
    spheres_clearance,
    spheres_collide,
)
from ntq_jax.geometry.world import KERNEL_COMPILER_OPTIONS, World, as_sequence_of_floats
from ntq_jax.geometry.world3d import World3D

__all__ = [
    "KERNEL_COMPILER_OPTIONS",
    "World",
    "as_sequence_of_floats",
    "sincos",
    "in_bounds",
    "point_hits_box",
    "point_hits_disc",
    "point_free",
    "segment_hits_box",
    "segment_hits_disc",
    "segment_free",
    "segment_cover_steps",
    "segment_hits_near",
    "segment_free_indexed",
    "RectPose",
    "rect_pose",
    "rect_corners",
    "rect_hits_box",
    "rect_hits_disc",
    "pose_hits_box",
    "pose_hits_disc",
    "rect_free",
    "segment_box_dist2",
    "segment_disc_dist",
    "rect_box_dist2",
    "rect_disc_dist",
    "pose_box_dist2",
    "pose_disc_dist",
    "wall_clearance",
    "segment_clearance",
    "rect_clearance",
    "rasterize",
    "cell_centers",
    "point_to_cell",
    "World3D",
    "NO_OBSTACLE_CLEARANCE",
    "point_sphere_dist",
    "point_cuboid_dist",
    "point_capsule_dist",
    "sphere_clearance",
    "spheres_clear",
    "spheres_clearance",
    "spheres_collide",
]
