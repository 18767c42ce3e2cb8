"""The ``"visgraph"`` planner: visibility-graph shortest paths for the point robot (the cost reference).

Usage::

    graph = VisGraph.build(env, padding=0.0)   # once per environment and padding
    res = graph.plan(queries)                  # queries (N, 2, 2): start, goal -> PlanResult
    res = plan_visgraph(env, queries, padding=0.0)   # cached graph + the exact check

*Per environment* (:meth:`VisGraph.build`): the nodes are the obstacle
vertices pushed outwards by a tiny ``eps`` (valid states only); node pairs are
tested with the package's one segment kernel (``env.steer_to``, both
directions); all-pairs shortest paths and their node sequences come from scipy.
*Per batch* (:meth:`VisGraph.plan`, one jitted call per chunk): start -> goal,
start -> node and node -> goal visibility with the same kernel, then
``cost = min(|s - g| if visible, min_ij |s - n_i| + D[i, j] + |n_j - g|)``; the
path is ``s, route(i*, j*), g``. The selection runs in float32; the reported
cost is the float64 sum of the returned path's segment lengths. Every segment
of a returned path was checked in the direction it is travelled, at the
planning padding, with the returned float32 coordinates.

Exactness (``L*(p)``: the shortest length among paths farther than ``p`` from
every obstacle, ``L`` the returned cost, ``k`` the bends of the optimal path;
always ``L >= L*(p)`` up to rounding, since every path is feasible):

* boxes at padding 0 (the evaluation geometry): ``L*(0) <= L <= L*(0) + 2
  sqrt(2) eps k``, assuming general position at the ``eps`` scale (a gap
  narrower than ``~2 eps`` may be missed). Default ``eps = 5e-5 x`` the
  workspace extent.
* curved boundaries (discs; box corners when ``p > 0``): each arc of radius
  ``R`` is replaced by its circumscribed polygon (tangents every ``beta <=
  arc_step``); visibility is still decided against the true padded obstacles.
  The polygons stick out by at most ``delta = R (1 / cos(beta / 2) - 1)``
  (``graph.delta``), so ``L <= L*_delta + 2 sqrt(2) eps k`` with ``L*_delta``
  the optimum among obstacles grown by the polygons; a passage narrower than
  ``delta`` may be missed.

Statuses are :class:`ntq_jax.types.PlanStatus` values: SOLVED, NO_PATH (no
path in the graph), INVALID (start or goal not a valid state at the planning
padding, or not finite); unsolved queries have ``cost = inf``, length 0 and an
all-NaN path row. Measurements: BENCHMARKS.md ("Classical planners").
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time

import jax
import jax.numpy as jnp
import numpy as np
from scipy.sparse.csgraph import shortest_path

from ntq_jax.batching import bucket_size, map_chunks
from ntq_jax.geometry import KERNEL_COMPILER_OPTIONS, World
from ntq_jax.planners.env_cache import EnvCache
from ntq_jax.planners.options import (
    float_option,
    int_option,
    motion_check_option,
    unsupported_robot,
)
from ntq_jax.planners.verify import finalize
from ntq_jax.robots.batch import is_valid_cm, steer_to_cm, steer_to_pairs, valid_states
from ntq_jax.types import PlanResult, PlanStatus

Array = jax.Array

#: Default node offset, relative to the workspace's larger side.
DEFAULT_EPS_REL = 5e-5
#: Default largest angle (radians) between consecutive tangents of an arc's circumscribed polygon.
DEFAULT_ARC_STEP = math.pi / 8
#: The node count and the route buffer are padded to multiples of this in :meth:`VisGraph.plan`
#: (maps with similar counts share the compiled code).
NODE_PAD = 8


# ---------------------------------------------------------------------------
# Graph construction (once per environment)
# ---------------------------------------------------------------------------


def obstacle_vertices(
    world: World, padding: float, eps: float, arc_step: float = DEFAULT_ARC_STEP
) -> np.ndarray:
    """Candidate graph nodes: obstacle vertices pushed outwards by ``eps`` (float64 ``(M, 2)``).

    Box corners at ``padding == 0``: ``corner + eps (sx, sy)`` with ``(sx, sy)``
    the corner's outward diagonal signs. With ``padding > 0`` each box corner
    is a quarter arc of radius ``padding``; discs are full arcs of radius
    ``r + padding``. An arc becomes the vertices of its circumscribed polygon
    (see the module docstring), each moved radially outwards by ``eps``. No
    validity filtering is done here.

    Args:
        world: the obstacles.
        padding: clearance (``>= 0``).
        eps: outward offset of every node (``> 0``).
        arc_step: largest angle between consecutive tangent lines of an arc.

    Returns:
        ``(M, 2)`` float64 candidate nodes, boxes first (corner by corner), then discs.
    """
    boxes = np.asarray(world.boxes, np.float64).reshape(-1, 4)
    discs = np.asarray(world.discs, np.float64).reshape(-1, 3)
    out = []
    corner_signs = np.array([(1, 1), (-1, 1), (-1, -1), (1, -1)], np.float64)  # quadrants 0..3
    for cx, cy, hw, hh in boxes:
        for q, (sx, sy) in enumerate(corner_signs):
            corner = np.array([cx + sx * hw, cy + sy * hh])
            if padding == 0.0:
                out.append(corner[None] + eps * np.array([[sx, sy]]))
            else:
                m = max(1, math.ceil((math.pi / 2) / arc_step - 1e-9))
                beta = (math.pi / 2) / m
                ang = q * (math.pi / 2) + (np.arange(m) + 0.5) * beta
                rad = padding / math.cos(beta / 2) + eps
                out.append(corner[None] + rad * np.stack([np.cos(ang), np.sin(ang)], 1))
    for cx, cy, r in discs:
        m = max(3, math.ceil(2 * math.pi / arc_step - 1e-9))
        beta = 2 * math.pi / m
        ang = (np.arange(m) + 0.5) * beta
        rad = (r + padding) / math.cos(beta / 2) + eps
        out.append(np.array([[cx, cy]]) + rad * np.stack([np.cos(ang), np.sin(ang)], 1))
    return np.concatenate(out, 0) if out else np.zeros((0, 2))


def _routes(pred: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Node sequences of all shortest paths from a scipy predecessor matrix.

    Args:
        pred: ``(V, V)`` int, ``pred[i, j]`` = node before ``j`` on the path from
            ``i`` (``-9999`` when none, as scipy returns).

    Returns:
        ``routes (V, V, R)`` int32: ``routes[i, j, :route_len[i, j]]`` is ``i, ..., j``
        (padded by repeating ``j``), and ``route_len (V, V)`` int32 (0 if unreachable).
    """
    v = pred.shape[0]
    ii, jj = np.meshgrid(np.arange(v), np.arange(v), indexing="ij")
    reach = (pred >= 0) | (ii == jj)
    back = [jj.copy()]  # walk j -> i backwards along the predecessors
    cur = jj.copy()
    for _ in range(v):
        active = reach & (cur != ii)
        if not active.any():
            break
        cur = np.where(active, pred[ii, np.maximum(cur, 0)], cur)
        back.append(cur.copy())
    back = np.stack(back, -1)  # (V, V, S): j, pred(j), ..., i, i, ...
    length = np.where(reach, 1 + np.sum(back[..., 1:] != back[..., :-1], -1), 0)
    r = max(int(length.max(initial=1)), 1)
    routes = np.empty((v, v, r), np.int32)
    k = np.arange(r)
    # routes[..., k] = back[..., length - 1 - k] for k < length, else j
    src = np.clip(length[..., None] - 1 - k, 0, back.shape[-1] - 1)
    routes[:] = np.where(k < length[..., None], np.take_along_axis(back, src, -1), jj[..., None])
    return routes, length.astype(np.int32)


# ---------------------------------------------------------------------------
# Queries (jitted, one call per chunk)
# ---------------------------------------------------------------------------


@functools.partial(
    jax.jit, static_argnames=("robot", "padding"), compiler_options=KERNEL_COMPILER_OPTIONS
)
def _solve(
    robot,
    world: World,
    nodes_cm: Array,
    dist: Array,
    routes: Array,
    route_len: Array,
    s_cm: Array,
    g_cm: Array,
    padding: float,
):
    """Plans a chunk of queries: statuses, first / last graph nodes and the assembled paths.

    Args:
        robot, world, padding: the geometry (``padding`` static).
        nodes_cm: ``(2, V)`` float32 nodes (NaN padding nodes are never visible).
        dist: ``(V, V)`` float32 all-pairs lengths; ``routes (V, V, R)`` int32 and
            ``route_len (V, V)`` int32 as in :class:`VisGraph`.
        s_cm, g_cm: ``(2, N)`` float32 starts and goals.

    Returns:
        ``status (N,)`` int8, ``via (N,)`` bool (the path uses graph nodes),
        ``first, last (N,)`` int32 its first and last node, ``length (N,)`` int32
        waypoint counts and ``paths (N, R + 2, 2)`` float32 NaN-padded.
    """
    n, v = s_cm.shape[1], nodes_cm.shape[1]
    valid = is_valid_cm(robot, world, s_cm, padding) & is_valid_cm(robot, world, g_cm, padding)
    direct = steer_to_cm(robot, world, s_cm, g_cm, padding)
    # every (query, node) pair as one flat coordinate-major batch for the shared kernel
    nodes_b = jnp.broadcast_to(nodes_cm[:, None, :], (2, n, v)).reshape(2, n * v)
    s_b = jnp.broadcast_to(s_cm[:, :, None], (2, n, v)).reshape(2, n * v)
    g_b = jnp.broadcast_to(g_cm[:, :, None], (2, n, v)).reshape(2, n * v)
    see_s = steer_to_cm(robot, world, s_b, nodes_b, padding).reshape(n, v)  # s -> node
    see_g = steer_to_cm(robot, world, nodes_b, g_b, padding).reshape(n, v)  # node -> g
    dsx, dsy = nodes_cm[0][None] - s_cm[0][:, None], nodes_cm[1][None] - s_cm[1][:, None]
    dgx, dgy = nodes_cm[0][None] - g_cm[0][:, None], nodes_cm[1][None] - g_cm[1][:, None]
    ds = jnp.where(see_s, jnp.sqrt(dsx * dsx + dsy * dsy), jnp.inf)  # (N, V)
    dg = jnp.where(see_g, jnp.sqrt(dgx * dgx + dgy * dgy), jnp.inf)
    # materialise: otherwise XLA fuses the segment kernel into the (N, V, V) reduction below
    # and evaluates it V times per pair
    ds, dg = jax.lax.optimization_barrier((ds, dg))
    to_goal = jnp.min(dist[None, :, :] + dg[:, None, :], axis=2)  # (N, V): node i -> g
    total = ds + to_goal
    first = jnp.argmin(total, axis=1).astype(jnp.int32)
    last = jnp.argmin(dist[first] + dg, axis=1).astype(jnp.int32)
    via = valid & ~direct & jnp.isfinite(jnp.min(total, axis=1))
    solved = valid & (direct | via)
    status = jnp.where(
        ~valid, PlanStatus.INVALID, jnp.where(solved, PlanStatus.SOLVED, PlanStatus.NO_PATH)
    ).astype(jnp.int8)
    inner = jnp.where(via, route_len[first, last], 0)
    length = jnp.where(solved, inner + 2, 0)
    # waypoint k: 0 -> start, 1..inner -> route nodes, inner + 1 -> goal, then NaN
    seq = routes[first, last]  # (N, R)
    k = jnp.arange(routes.shape[-1] + 2)[None, :]
    coords = []
    for d in range(2):
        pts = nodes_cm[d][seq]
        pts = jnp.concatenate([pts[:, :1], pts, pts[:, :1]], axis=1)  # aligned with k
        c = jnp.where(
            k == 0,
            s_cm[d][:, None],
            jnp.where(
                k <= inner[:, None],
                pts,
                jnp.where(k == inner[:, None] + 1, g_cm[d][:, None], jnp.nan),
            ),
        )
        coords.append(jnp.where(solved[:, None], c, jnp.nan))
    return status, via, first, last, length, jnp.stack(coords, axis=-1)


# ---------------------------------------------------------------------------
# Public API
# ---------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True, eq=False)
class VisGraph:
    """A visibility graph of one environment at one padding (build with :meth:`build`).

    Attributes:
        robot: the (point) robot, ``world``: the obstacles, ``padding``: the planning clearance.
        eps: the outward node offset; ``arc_step``: the arc polygon step (radians).
        delta: largest distance by which the circumscribed arc polygons stick out
            of the true padded obstacles (0 when the graph is exact up to ``eps``).
        nodes: ``(V, 2)`` float32 valid nodes (the coordinates every check used).
        visible: ``(V, V)`` bool, the segment between two nodes is free (both directions).
        dist: ``(V, V)`` float64 all-pairs shortest lengths (``inf`` if disconnected).
        routes: ``(V, V, R)`` int32 node sequences ``i .. j`` (padded with ``j``);
            ``route_len``: ``(V, V)`` int32 their lengths (0 if disconnected).
    """

    robot: object
    world: World
    padding: float
    eps: float
    arc_step: float
    delta: float
    nodes: np.ndarray
    visible: np.ndarray
    dist: np.ndarray
    routes: np.ndarray
    route_len: np.ndarray

    @property
    def exact(self) -> bool:
        """True when the graph is exact up to the ``eps`` node offset (boxes only, padding 0)."""
        return self.delta == 0.0

    @property
    def num_nodes(self) -> int:
        return int(self.nodes.shape[0])

    @staticmethod
    def build(
        env,
        padding: float | None = None,
        *,
        eps: float | None = None,
        arc_step: float = DEFAULT_ARC_STEP,
    ) -> "VisGraph":
        """Builds the graph of ``env`` (a point-robot :class:`ntq_jax.Env`).

        Args:
            env: the environment; its robot must be a point robot.
            padding: clearance; ``None`` is the environment's own padding (the
                data-generation geometry), ``0.0`` the evaluation geometry (exact).
            eps: node offset (default ``5e-5 x`` the workspace's larger side).
            arc_step: largest tangent step (radians) of the arc polygons.

        Raises:
            ValueError: not a point robot, or bad ``eps`` / ``arc_step``.
        """
        if env.robot.kind != "point":
            raise ValueError(
                f"the visibility graph plans for a point robot, got {env.robot.kind!r}"
            )
        pad = env.resolve_padding(padding)
        bounds = np.asarray(env.world.bounds, np.float64)
        if eps is None:
            eps = DEFAULT_EPS_REL * float(np.max(bounds[:, 1] - bounds[:, 0]))
        if not (math.isfinite(eps) and eps > 0):
            raise ValueError(f"eps must be > 0, got {eps!r}")
        if not (0 < arc_step <= math.pi / 2):
            raise ValueError(f"arc_step must be in (0, pi/2], got {arc_step!r}")
        cand = obstacle_vertices(env.world, pad, eps, arc_step).astype(np.float32)
        if len(cand):
            keep = valid_states(env.robot, env.world, cand, pad)
            cand = np.unique(cand[keep], axis=0)  # coincident corners: one node
        nodes = np.ascontiguousarray(cand)
        v = len(nodes)
        ii, jj = np.triu_indices(v, 1)
        visible = np.zeros((v, v), bool)
        if len(ii):
            vis = steer_to_pairs(env.robot, env.world, nodes[ii], nodes[jj], pad) & steer_to_pairs(
                env.robot, env.world, nodes[jj], nodes[ii], pad
            )
            visible[ii, jj] = visible[jj, ii] = vis
        n64 = nodes.astype(np.float64)
        edge = np.linalg.norm(n64[:, None] - n64[None], axis=-1)
        weights = np.where(visible, edge, 0.0)  # 0 = no edge for scipy's dense input
        if v:
            dist, pred = shortest_path(
                weights, method="D", directed=False, return_predecessors=True
            )
        else:
            dist, pred = np.zeros((0, 0)), np.zeros((0, 0), np.int32)
        routes, route_len = _routes(pred)
        delta = 0.0
        if pad > 0 and env.world.num_boxes:
            m = max(1, math.ceil((math.pi / 2) / arc_step - 1e-9))
            delta = pad * (1 / math.cos((math.pi / 2) / m / 2) - 1)
        if env.world.num_discs:
            m = max(3, math.ceil(2 * math.pi / arc_step - 1e-9))
            r_max = float(np.max(np.asarray(env.world.discs)[:, 2])) + pad
            delta = max(delta, r_max * (1 / math.cos(math.pi / m) - 1))
        return VisGraph(
            env.robot,
            env.world,
            pad,
            float(eps),
            float(arc_step),
            float(delta),
            nodes,
            visible,
            dist,
            routes,
            route_len,
        )

    def _padded_tables(self, table_size: int = 0) -> tuple[Array, Array, Array, Array]:
        """``(nodes_cm, dist, routes, route_len)`` padded to multiples of ``NODE_PAD`` (and to at
        least ``table_size``) for :func:`_solve`.

        Padding nodes are NaN (never visible), so maps with similar node counts
        share the compiled code; routes are padded by repeating their last node.
        """
        v = self.num_nodes
        vp = max(NODE_PAD, -(-v // NODE_PAD) * NODE_PAD, table_size)
        r0 = self.routes.shape[-1] if v else 1
        r = max(NODE_PAD, -(-r0 // NODE_PAD) * NODE_PAD, table_size)  # route buffer: the same
        nodes_cm = np.full((2, vp), np.nan, np.float32)
        nodes_cm[:, :v] = self.nodes.T
        dist32 = np.full((vp, vp), np.inf, np.float32)
        dist32[:v, :v] = self.dist
        routes = np.zeros((vp, vp, r), np.int32)
        routes[:v, :v, :r0] = self.routes
        routes[:v, :v, r0:] = self.routes[:, :, -1:]
        route_len = np.zeros((vp, vp), np.int32)
        route_len[:v, :v] = self.route_len
        return tuple(jnp.asarray(a) for a in (nodes_cm, dist32, routes, route_len))

    def plan(self, queries, *, chunk_size: int = 8192, table_size: int = 0) -> PlanResult:
        """Shortest paths for a batch of queries.

        Args:
            queries: ``(N, 2, 2)`` (start, goal) points; cast to float32.
            chunk_size: queries per jitted call (batches are padded to a power
                of two up to this size, so repeated calls reuse the compiled code).
            table_size: pad the node tables and the route buffer to at least this
                many nodes (NaN nodes, never visible). Graphs of maps with the same
                obstacle counts and padding plan with one compiled program when it is
                their candidate count, ``len(obstacle_vertices(world, padding, eps,
                arc_step))`` (no graph has more nodes). The answers do not depend on it.

        Returns:
            A :class:`PlanResult` (costs as described in the module docstring;
            ``info``: ``planner``, ``nodes``, ``exact``, ``delta``).
        """
        q = np.asarray(queries, np.float32)
        if q.ndim != 3 or q.shape[1:] != (2, 2):
            raise ValueError(f"queries must have shape (N, 2, 2), got {q.shape}")
        tables = self._padded_tables(int(table_size))
        width = tables[2].shape[-1] + 2
        empty = (
            np.zeros(0, np.int8),
            np.zeros(0, bool),
            np.zeros(0, np.int32),
            np.zeros(0, np.int32),
            np.zeros(0, np.int32),
            np.zeros((0, width, 2), np.float32),
        )
        status, via, first, last, length, paths = map_chunks(
            lambda part: _solve(
                self.robot,
                self.world,
                *tables,
                jnp.asarray(part[:, 0].T),
                jnp.asarray(part[:, 1].T),
                self.padding,
            ),
            q,
            chunk=bucket_size(min(q.shape[0], chunk_size), 64),
            empty=empty,
        )
        # float64 costs: |s - n_first| + dist[first, last] + |n_last - g|, or |s - g|
        s64, g64 = q[:, 0].astype(np.float64), q[:, 1].astype(np.float64)
        costs = np.linalg.norm(g64 - s64, axis=1)
        if self.num_nodes:
            nodes64 = self.nodes.astype(np.float64)
            f, l = np.where(via, first, 0), np.where(via, last, 0)
            graph_cost = (
                np.linalg.norm(nodes64[f] - s64, axis=1)
                + self.dist[f, l]
                + np.linalg.norm(g64 - nodes64[l], axis=1)
            )
            costs = np.where(via, graph_cost, costs)
        costs = np.where(status == PlanStatus.SOLVED, costs, np.inf)
        width = max(2, int(length.max(initial=0)))
        info = {
            "planner": "visgraph",
            "nodes": self.num_nodes,
            "exact": self.exact,
            "delta": self.delta,
        }
        return PlanResult(np.ascontiguousarray(paths[:, :width]), length, costs, status, info)


_GRAPHS = EnvCache(per_env=4)


#: The most obstacles (boxes + discs) the visibility graph is built for: its all-pairs
#: tables grow with the square of the node count (4 per box, more with padding), so a
#: map imported from a grid (thousands of boxes) is refused with a clear message; the
#: reference there is grid A* on the map's own grid.
MAX_OBSTACLES = 500


def check_size(env) -> None:
    """ValueError when ``env`` has more than :data:`MAX_OBSTACLES` obstacles (see there)."""
    n = env.world.num_boxes + env.world.num_discs
    if n > MAX_OBSTACLES:
        raise ValueError(
            f"the 'visgraph' planner builds all-pairs tables and is limited to "
            f"{MAX_OBSTACLES} obstacles; {env.name} has {n}: use 'astar' (on a map "
            "imported from a grid it plans on the map's own cells) or 'bitstar'"
        )


def plan_visgraph(
    env,
    queries,
    *,
    padding: float | None = None,
    seed: int = 0,
    eps: float | None = None,
    arc_step: float | None = None,
    chunk_size: int = 8192,
    check: str = "discretized",
) -> PlanResult:
    """Plans on ``env``'s visibility graph (built once per environment and settings, cached
    while ``env`` lives) and verifies every path (the registry's ``"visgraph"``).

    Args:
        env: a point-robot environment.
        queries: ``(N, 2, 2)`` (start, goal) points.
        padding: clearance; ``None`` = the environment's padding, ``0.0`` = the
            evaluation geometry (exact for boxes).
        seed: unused (deterministic).
        eps, arc_step: :meth:`VisGraph.build` options (``None``: the defaults).
        chunk_size: queries per jitted call.
        check: the motion check of the final verification (for the point robot both
            checks are the exact segment test).

    Returns:
        A :class:`PlanResult` checked by :func:`ntq_jax.planners.verify.finalize`.

    Raises:
        ValueError: not a point robot; TypeError, ValueError: an option of the
            wrong type or out of range (the message names it).
    """
    del seed  # deterministic
    eps = float_option("visgraph", "eps", eps, none_ok=True)
    arc_step = float_option("visgraph", "arc_step", arc_step, maximum=math.pi / 2, none_ok=True)
    chunk_size = int_option("visgraph", "chunk_size", chunk_size, 1)
    check = motion_check_option("visgraph", check)
    why = unsupported_robot("visgraph", env)
    if why:
        raise ValueError(why)
    check_size(env)
    pad = env.resolve_padding(padding)
    q = np.asarray(queries, np.float32)
    step = DEFAULT_ARC_STEP if arc_step is None else arc_step
    t0 = time.perf_counter()
    graph = _GRAPHS.get(
        env, (pad, eps, step), lambda: VisGraph.build(env, pad, eps=eps, arc_step=step)
    )
    t1 = time.perf_counter()
    res = graph.plan(q, chunk_size=chunk_size)
    info = dict(res.info, build_time=t1 - t0, plan_time=time.perf_counter() - t1)
    out = finalize(q, res.paths, res.lengths, res.status, info, env, pad, check)
    info["time"] = time.perf_counter() - t0
    return out


# ---------------------------------------------------------------------------
# Throughput measurement
# ---------------------------------------------------------------------------


def benchmark_visgraph(
    env, n: int = 100_000, *, padding: float = 0.0, seed: int = 0, repeats: int = 3, **build_options
) -> dict:
    """Measures build time and planning throughput (costs and paths) on ``n`` uniform queries.

    Starts and goals are drawn uniformly among valid states (``env.sample_states``).
    The first :meth:`VisGraph.plan` call (compilation) is not timed; the best of
    ``repeats`` timed calls is reported.

    Returns:
        A dict: ``env``, ``padding``, ``nodes``, ``build_s``, ``n``, ``plan_s``,
        ``queries_per_s``, ``solved`` (fraction), ``direct`` (fraction of 2-point paths),
        ``devices`` (JAX CPU device count).
    """
    key = jax.random.PRNGKey(seed)
    k1, k2 = jax.random.split(key)
    pad = env.resolve_padding(padding)
    q = np.stack([env.sample_states(k1, n, pad), env.sample_states(k2, n, pad)], 1)
    t0 = time.perf_counter()
    graph = VisGraph.build(env, pad, **build_options)
    build_s = time.perf_counter() - t0
    res = graph.plan(q)  # compile
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        res = graph.plan(q)
        best = min(best, time.perf_counter() - t0)
    return {
        "env": env.name,
        "padding": pad,
        "nodes": graph.num_nodes,
        "build_s": build_s,
        "n": n,
        "plan_s": best,
        "queries_per_s": n / best,
        "solved": float(np.mean(res.solved)),
        "direct": float(np.mean(res.lengths == 2)),
        "devices": jax.device_count(),
    }


__all__ = [
    "VisGraph",
    "plan_visgraph",
    "obstacle_vertices",
    "benchmark_visgraph",
    "DEFAULT_ARC_STEP",
    "DEFAULT_EPS_REL",
]
