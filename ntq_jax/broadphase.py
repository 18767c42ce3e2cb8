"""Obstacle-count scaling: looped obstacle folds and a uniform-grid broad phase.

The collision kernels of :mod:`ntq_jax.geometry` unroll their obstacle loop at
trace time: fastest for the few obstacles of the presets, but compile time and
memory grow with the obstacle count (2,000 boxes: about a minute and gigabytes).
Above :data:`UNROLL_MAX` obstacles they use the two tools of this module instead:

* :func:`fold`: the same per-obstacle test, looped (``lax.fori_loop`` over
  blocks of :data:`BLOCK` obstacles unrolled inside), so the compiled program
  does not grow with the count. Same formula per obstacle, same answers.
* :class:`ObstacleIndex`, the broad phase: the workspace cut into a uniform
  grid of ``nx x ny`` square cells of side ``cell``; each cell keeps a copy of
  the boxes within ``reach`` of it (``K`` rows, padded with far-away sentinel
  boxes). A shape whose every point is within ``rho`` of a query point ``p``
  can only touch, at clearance ``padding``, the boxes listed in ``p``'s cell
  when ``padding + rho <= reach``: the point robot (``rho = 0``) and the rigid
  body (``rho`` its half diagonal) test the ``K`` boxes of one cell. A segment
  is covered by points ``2 h`` apart (``h = reach - padding``), and tested
  exactly, as a whole, against the boxes of each of their cells; the batched
  point-robot ``steer_to`` runs these cells through a work queue (see
  :mod:`ntq_jax.robots.point`). Every narrow-phase test is the exact kernel of
  :mod:`ntq_jax.geometry`, so the answers equal the unrolled kernels' (the
  candidate lists are complete, with a slack for float32 rounding).

A World gets an index from :func:`with_index` (``Env`` adds one to maps with
more than :data:`UNROLL_MAX` boxes, with a ``reach`` that covers its robot and
padding). A query whose ``padding + rho`` exceeds the reach falls back to the
looped fold over all boxes: slower, same answers. Discs are not indexed (the
looped fold above :data:`UNROLL_MAX` discs). Clearances (the certified check)
from the index are exact up to a cap, ``reach - rho``: a lower bound of the
true distance that is exact whenever the distance is below the cap, which is
all the certified check's proof needs.

The index also keeps a *blocked-cell bitmap* for the point robot's batched
``steer_to`` (:attr:`ObstacleIndex.blocked`): a second uniform grid from the
same corner, its own cell side ``bcell`` (the thinnest box's extent, or a
fraction of it no larger than the index cell, so that the cells of an imported
occupancy grid are the grid's own cells; at most :data:`BITMAP_MAX_CELLS`
cells, :func:`bitmap_cell`), one byte per cell, set when the closed
cell lies inside one box (computed on the host; exact for grid-derived maps,
conservative for arbitrary boxes: a cell covered only by the union of several
boxes is not set). A point at least ``margin`` inside a set cell
(:meth:`ObstacleIndex.certainly_blocked`) is inside a box by more than the
float32 rounding of the queries' interpolated points, so a segment through it
is blocked at every padding ``>= 0`` (the exact kernels agree: their tests hold
with a slack of about ``margin |b - a|``). The bitmap only ever says "blocked";
everything it leaves undecided goes through the exact narrow phase. A map with
fewer than :data:`BITMAP_MIN_FILL` of its cells set (e.g. scattered small boxes)
keeps ``blocked = None``: the first pass is then left out at trace time.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from ntq_jax.validation import check_padding, check_positive

Array = jax.Array

#: Obstacle counts (boxes, discs, or an index cell's candidates) up to which the kernels
#: unroll their loop at trace time (one fused expression per obstacle; every preset has
#: at most a few dozen obstacles). Above it, the
#: kernels loop (:func:`fold`) and ``Env`` gives the world a broad-phase index.
UNROLL_MAX = 64

#: Obstacles per unrolled block of the looped fold.
BLOCK = 8

#: Candidates per unrolled block when a kernel loops over an index cell's list
#: (:func:`fold_candidates`): the list's length is a multiple of it.
INDEX_BLOCK = 4

#: Candidate lists up to this length are unrolled by the cheap tests (point, segment,
#: rectangle intersection); the distance kernels of the certified check always loop.
INDEX_UNROLL_MAX = 16

#: Sentinel box ``[cx, cy, half_w, half_h]`` padding the index's candidate lists: far from
#: any workspace (no test against it is ever true, and its squares stay finite in float32).
SENTINEL_BOX = (1.0e7, 1.0e7, 1.0, 1.0)

#: The most cells of an index (``nx * ny``).
MAX_CELLS = 256 * 256

#: Target mean number of boxes per cell when the cell size is derived from the map.
BOXES_PER_CELL = 0.125

#: The most cells of the blocked-cell bitmap (one byte each).
BITMAP_MAX_CELLS = 1024 * 1024

#: The least fraction of set cells for which an index keeps its blocked-cell bitmap: with
#: fewer, the bitmap decides too few segments to pay for its reads (BENCHMARKS.md).
BITMAP_MIN_FILL = 0.1


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class ObstacleIndex:
    """A uniform grid of candidate boxes over the workspace (see the module docstring).

    Attributes:
        boxes: ``(nx * ny, K, 4)`` float32: cell ``row * nx + col``'s candidate boxes,
            every box within ``reach`` of the cell, then sentinels.
        x0, y0: the lower-left corner of the grid (static).
        cell: the cells' side (static).
        nx, ny: the grid's columns and rows (static).
        reach: the distance from a cell within which every box is listed (static).
        blocked: None, or the blocked-cell bitmap (see the module docstring):
            ``(bny * bnx,)`` uint8, cell ``row * bnx + col`` is 1 when the closed cell
            lies inside one box.
        bcell, bnx, bny: the bitmap's cell side, columns and rows (static; its lower-left
            corner is the grid's, ``(x0, y0)``).
        margin: how far inside a set bitmap cell a point must be for
            :meth:`certainly_blocked` (static, in world units).
    """

    boxes: Array
    x0: float = dataclasses.field(metadata=dict(static=True))
    y0: float = dataclasses.field(metadata=dict(static=True))
    cell: float = dataclasses.field(metadata=dict(static=True))
    nx: int = dataclasses.field(metadata=dict(static=True))
    ny: int = dataclasses.field(metadata=dict(static=True))
    reach: float = dataclasses.field(metadata=dict(static=True))
    blocked: Array | None = None
    bcell: float = dataclasses.field(default=1.0, metadata=dict(static=True))
    bnx: int = dataclasses.field(default=0, metadata=dict(static=True))
    bny: int = dataclasses.field(default=0, metadata=dict(static=True))
    margin: float = dataclasses.field(default=0.0, metadata=dict(static=True))

    @property
    def capacity(self) -> int:
        """``K``, the candidate rows per cell."""
        return int(self.boxes.shape[1])

    def cell_of(self, x: Array, y: Array) -> Array:
        """The cell id of ``(x, y)`` (clamped to the grid; 0 for NaN)."""
        col = jnp.floor((x - self.x0) * jnp.float32(1.0 / self.cell))
        row = jnp.floor((y - self.y0) * jnp.float32(1.0 / self.cell))
        col = jnp.clip(jnp.where(jnp.isfinite(col), col, 0.0), 0, self.nx - 1).astype(jnp.int32)
        row = jnp.clip(jnp.where(jnp.isfinite(row), row, 0.0), 0, self.ny - 1).astype(jnp.int32)
        return row * self.nx + col

    def candidates(self, x: Array, y: Array) -> Array:
        """``(K, 4)``: the boxes listed in the cell of ``(x, y)``."""
        return self.boxes[self.cell_of(x, y)]

    def certainly_blocked(self, x: Array, y: Array) -> Array:
        """True when ``(x, y)`` is at least :attr:`margin` inside a set cell of the
        blocked-cell bitmap, hence inside a box (False without a bitmap, outside the
        grid and for NaN)."""
        if self.blocked is None:
            return jnp.zeros(jnp.broadcast_shapes(jnp.shape(x), jnp.shape(y)), bool)
        inv = jnp.float32(1.0 / self.bcell)
        m = jnp.float32(self.margin / self.bcell)
        u, v = (x - self.x0) * inv, (y - self.y0) * inv
        col, row = jnp.floor(u), jnp.floor(v)
        fu, fv = u - col, v - row
        inside = (
            (fu >= m)
            & (fu <= 1.0 - m)
            & (fv >= m)
            & (fv <= 1.0 - m)
            & (col >= 0.0)
            & (col < self.bnx)
            & (row >= 0.0)
            & (row < self.bny)
        )
        col = jnp.clip(jnp.where(inside, col, 0.0), 0, self.bnx - 1).astype(jnp.int32)
        row = jnp.clip(jnp.where(inside, row, 0.0), 0, self.bny - 1).astype(jnp.int32)
        return inside & (self.blocked.at[row * self.bnx + col].get(mode="promise_in_bounds") != 0)


def fold(
    rows: Array, f, init, combine, sentinel=None, unroll_max: int | None = None, block: int = BLOCK
):
    """``combine(acc, f(row))`` over the rows of ``rows`` (``(n, w)``), starting from ``init``.

    Unrolled at trace time for ``n <= unroll_max`` (default :data:`UNROLL_MAX`);
    otherwise a ``lax.fori_loop`` over blocks of ``block`` rows (unrolled
    inside), the last block padded with ``sentinel`` rows (which must not change
    ``acc``), so the compiled size does not depend on ``n``.
    """
    n = int(rows.shape[0])
    acc = init
    if n <= (UNROLL_MAX if unroll_max is None else unroll_max):
        for i in range(n):
            acc = combine(acc, f(rows[i]))
        return acc
    blocks = -(-n // block)
    if blocks * block > n:
        pad = jnp.broadcast_to(
            jnp.asarray(sentinel, rows.dtype), (blocks * block - n, rows.shape[1])
        )
        rows = jnp.concatenate([rows, pad])

    def body(j, acc):
        blk = jax.lax.dynamic_slice_in_dim(rows, j * block, block)
        for i in range(block):
            acc = combine(acc, f(blk[i]))
        return acc

    return jax.lax.fori_loop(0, blocks, body, acc)


def fold_candidates(rows: Array, f, init, combine, cheap: bool = True):
    """:func:`fold` over an index cell's candidate boxes (``(K, 4)``): unrolled up to
    :data:`INDEX_UNROLL_MAX` candidates for ``cheap`` tests, else looped in blocks of
    :data:`INDEX_BLOCK` (the heavier distance kernels: their compile time stays small)."""
    return fold(
        rows,
        f,
        init,
        combine,
        SENTINEL_BOX,
        unroll_max=INDEX_UNROLL_MAX if cheap else 0,
        block=INDEX_BLOCK,
    )


def choose_cell(bounds: np.ndarray, num_boxes: int, min_cell: float = 0.0) -> float:
    """A cell side for :func:`build_index`: about :data:`BOXES_PER_CELL` boxes per cell of the
    workspace, at least ``min_cell``, and at most :data:`MAX_CELLS` cells."""
    b = np.asarray(bounds, np.float64)
    w, h = b[0, 1] - b[0, 0], b[1, 1] - b[1, 0]
    cell = math.sqrt(w * h * BOXES_PER_CELL / max(num_boxes, 1))
    cell = max(cell, min_cell, math.sqrt(w * h / MAX_CELLS))
    return float(min(cell, max(w, h)))


def build_index(bounds, boxes, reach: float, cell: float | None = None) -> ObstacleIndex:
    """The broad-phase index of ``boxes`` (``(B, 4)``) over ``bounds`` at ``reach`` (host NumPy).

    ``cell`` (default :func:`choose_cell` with ``min_cell = reach``). A box is
    listed in every cell whose square is within ``reach`` of it (plus a slack of
    ``1e-3 cell + 1e-5 * |coordinates|`` that absorbs the float32 rounding of the
    queries' cell lookup and interpolated points).
    """
    b = np.asarray(bounds, np.float64)
    bx = np.asarray(boxes, np.float64).reshape(-1, 4)
    reach = check_padding(reach, "reach")
    if cell is None:
        cell = choose_cell(b, len(bx), min_cell=reach)
    cell = check_positive("cell", cell)
    x0, y0 = float(b[0, 0]), float(b[1, 0])
    nx = max(1, math.ceil((b[0, 1] - x0) / cell))
    ny = max(1, math.ceil((b[1, 1] - y0) / cell))
    scale = float(np.max(np.abs(b))) if b.size else 1.0
    slack = 1e-3 * cell + 1e-5 * max(scale, float(np.max(np.abs(bx[:, :2]), initial=0.0)))
    r = reach + slack
    lists: list[list[int]] = [[] for _ in range(nx * ny)]
    for i, (cx, cy, hw, hh) in enumerate(bx):
        c0 = max(0, math.floor((cx - hw - r - x0) / cell))
        c1 = min(nx - 1, math.floor((cx + hw + r - x0) / cell))
        r0 = max(0, math.floor((cy - hh - r - y0) / cell))
        r1 = min(ny - 1, math.floor((cy + hh + r - y0) / cell))
        if c0 > c1 or r0 > r1:
            continue
        cols = np.arange(c0, c1 + 1)
        rows = np.arange(r0, r1 + 1)
        dx = np.maximum(np.abs(x0 + (cols + 0.5) * cell - cx) - hw - 0.5 * cell, 0.0)
        dy = np.maximum(np.abs(y0 + (rows + 0.5) * cell - cy) - hh - 0.5 * cell, 0.0)
        near = dy[:, None] ** 2 + dx[None, :] ** 2 <= r * r
        for rr, cc in zip(*np.nonzero(near)):
            lists[(r0 + rr) * nx + c0 + cc].append(i)
    k = max(1, max(len(v) for v in lists))
    k = -(-k // INDEX_BLOCK) * INDEX_BLOCK  # whole blocks of the candidates' fold
    table = np.tile(np.asarray(SENTINEL_BOX, np.float32), (nx * ny, k, 1))
    for c, v in enumerate(lists):
        if v:
            table[c, : len(v)] = bx[v]
    extent = float(np.max(np.abs(bx[:, :2]) + bx[:, 2:], initial=0.0))
    bitmap = blocked_bitmap(b, bx, float(cell), max(scale, extent))
    if bitmap is None:
        return ObstacleIndex(
            jnp.asarray(table), x0, y0, float(cell), int(nx), int(ny), float(reach)
        )
    blocked, bcell, margin = bitmap
    return ObstacleIndex(
        jnp.asarray(table),
        x0,
        y0,
        float(cell),
        int(nx),
        int(ny),
        float(reach),
        jnp.asarray(blocked.ravel()),
        bcell,
        int(blocked.shape[1]),
        int(blocked.shape[0]),
        margin,
    )


def bitmap_cell(bounds: np.ndarray, boxes: np.ndarray, cell: float) -> float:
    """The blocked-cell bitmap's cell side: the thinnest box's extent ``thin`` (the grid's
    resolution for an imported occupancy grid, whose walls are at least one grid cell thick:
    the bitmap's cells are then the grid's cells), divided by the smallest integer that makes
    it no larger than the index ``cell``; when that would make more than :data:`BITMAP_MAX_CELLS`
    cells (up to rounding), the smallest multiple of ``thin`` that does not instead."""
    b = np.asarray(bounds, np.float64)
    w, h = b[0, 1] - b[0, 0], b[1, 1] - b[1, 0]
    thin = float(2.0 * np.min(boxes[:, 2:])) if len(boxes) else cell
    if not thin > 0:
        return cell
    bcell = thin / max(1, math.ceil(thin / cell * (1.0 - 1e-6)))  # float32 boxes
    floor = math.sqrt(w * h / BITMAP_MAX_CELLS)
    if bcell < floor:
        bcell = thin * math.ceil(floor / thin * (1.0 - 1e-6))
    return bcell


def _round_up_2(x: float) -> float:
    """``x > 0`` rounded up to two significant digits: maps that differ only in the last digits
    of their extent get the same (static) ``margin``, hence share compiled programs."""
    step = 10.0 ** (math.floor(math.log10(x)) - 1)
    return math.ceil(x / step * (1.0 - 1e-12)) * step


def blocked_bitmap(bounds, boxes, cell: float, scale: float, min_fill: float | None = None):
    """``(blocked, bcell, margin)`` of the blocked-cell bitmap (module docstring), or None
    when fewer than ``min_fill`` (default :data:`BITMAP_MIN_FILL`) of its cells are blocked
    (``scale``: the largest coordinate of the bounds and boxes, which sets the float32
    rounding the ``margin`` must absorb; the margin is rounded up to two significant
    digits): ``blocked`` ``(bny, bnx)`` uint8 is 1 where the closed cell
    ``[x0 + c bcell, x0 + (c + 1) bcell] x [...]`` lies inside one box (up to a tolerance
    of ``margin / 2``, which :meth:`ObstacleIndex.certainly_blocked` leaves as slack)."""
    b = np.asarray(bounds, np.float64)
    bx = np.asarray(boxes, np.float64).reshape(-1, 4)
    min_fill = BITMAP_MIN_FILL if min_fill is None else min_fill
    if not len(bx):
        return None
    bcell = bitmap_cell(b, bx, cell)
    x0, y0 = float(b[0, 0]), float(b[1, 0])
    nx = max(1, math.ceil((b[0, 1] - x0) / bcell * (1.0 - 1e-6)))  # cells past the bounds: 0
    ny = max(1, math.ceil((b[1, 1] - y0) / bcell * (1.0 - 1e-6)))
    margin = _round_up_2(1e-3 * bcell + 1e-5 * max(scale, 1.0))
    if margin >= 0.25 * bcell:
        return None
    tol = 0.5 * margin
    # cells [x0 + c bcell, x0 + (c + 1) bcell] within [cx - hw - tol, cx + hw + tol]
    c0 = np.maximum(np.ceil((bx[:, 0] - bx[:, 2] - tol - x0) / bcell), 0)
    c1 = np.minimum(np.floor((bx[:, 0] + bx[:, 2] + tol - x0) / bcell) - 1, nx - 1)
    r0 = np.maximum(np.ceil((bx[:, 1] - bx[:, 3] - tol - y0) / bcell), 0)
    r1 = np.minimum(np.floor((bx[:, 1] + bx[:, 3] + tol - y0) / bcell) - 1, ny - 1)
    # the float division above may round an edge cell in: keep only cells whose edges
    # really are within the grown box
    c0 = c0 + (x0 + c0 * bcell < bx[:, 0] - bx[:, 2] - tol)
    c1 = c1 - (x0 + (c1 + 1) * bcell > bx[:, 0] + bx[:, 2] + tol)
    r0 = r0 + (y0 + r0 * bcell < bx[:, 1] - bx[:, 3] - tol)
    r1 = r1 - (y0 + (r1 + 1) * bcell > bx[:, 1] + bx[:, 3] + tol)
    # a 2-D difference array: +1 at (r0, c0), -1 past the corners, then prefix sums
    keep = (c0 <= c1) & (r0 <= r1)
    c0, c1, r0, r1 = (v[keep].astype(np.int64) for v in (c0, c1, r0, r1))
    if not len(c0):
        return None
    diff = np.zeros((ny + 1, nx + 1), np.int64)
    np.add.at(diff, (r0, c0), 1)
    np.add.at(diff, (r0, c1 + 1), -1)
    np.add.at(diff, (r1 + 1, c0), -1)
    np.add.at(diff, (r1 + 1, c1 + 1), 1)
    blocked = (np.cumsum(np.cumsum(diff, 0), 1)[:ny, :nx] > 0).astype(np.uint8)
    if blocked.mean() < min_fill:
        return None
    return blocked, float(bcell), float(margin)


def with_index(world, reach: float, cell: float | None = None):
    """``world`` with a broad-phase :class:`ObstacleIndex` of its boxes at ``reach``."""
    return dataclasses.replace(world, index=build_index(world.bounds, world.boxes, reach, cell))


def index_covers(world, padding: float, rho: float = 0.0, strict: bool = False) -> bool:
    """True when ``world`` has an index and a shape within ``rho`` of a query point, at
    clearance ``padding``, needs only the query cell's candidates (``padding + rho <= reach``;
    ``<`` with ``strict``). Static: decided at trace time."""
    index = getattr(world, "index", None)
    if index is None:
        return False
    return padding + rho < index.reach if strict else padding + rho <= index.reach
