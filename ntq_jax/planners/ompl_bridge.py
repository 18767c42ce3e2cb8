"""OMPL BIT* as a planner of the package: :func:`plan_bitstar`, the ``"bitstar"`` planner.

Contract: ``plan_bitstar(env, queries (N, 2, d), ...) -> PlanResult``. Each
valid query gets ``time_budget`` seconds of BIT*
(:class:`ntq_jax.planners.ompl_worker.OmplProblem`, on the package's geometry
through :class:`ntq_jax.planners.ompl_checker.NumpyChecker`) in parallel worker
processes; BIT*'s raw paths are then verified, and their costs computed, by the
one path checker, :func:`ntq_jax.planners.verify.finalize`. The bridge's own
per-query :class:`BridgeOutcome` (kept in ``info["bitstar_status"]``) maps to
:class:`ntq_jax.types.PlanStatus` once, in :data:`PLAN_STATUS`. An unsolvable,
invalid or crashing query is a status, never an exception. A 3-D serial arm (the
Panda), whose geometry exists only in JAX, is handed to the in-process route
:func:`ntq_jax.planners.ompl_rrtconnect.plan_bitstar_jax` (the same BIT* on the JAX
checks); the planar robots' route does not change.

Workers are started with ``spawn`` (never fork: the parent has JAX and its
threads loaded) WITHOUT importing the caller's ``__main__`` module (see
:func:`_main_hidden`): everything a worker needs lives in ``ntq_jax``, so a
user's script calling :func:`plan_bitstar` at top level, without an
``if __name__ == "__main__":`` guard, is not re-run by each worker (with
multiprocessing's default it would be, and every worker would die starting).
A worker that dies (killed, segfault in native code) has the query it was
solving retried once in a fresh worker (CRASHED if it kills that one too) and
its other queries re-queued.

Determinism: before each query the worker re-seeds OMPL with
``query_seeds(seed, N)[i]`` and builds a fresh planner, so the samples do not
depend on which worker solves the query. With ``stop_on_first=True`` results
are reproducible run to run; with the full budget (default) they depend on how
far BIT* gets before the wall-clock deadline. Throughput and callback costs:
``benchmarks/bench_bitstar.py`` and BENCHMARKS.md.
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import importlib.util
import math
import multiprocessing as mp
import os
import pickle
import sys
import threading
import time
import types
import warnings
from multiprocessing.connection import wait as _mp_wait
from typing import Mapping

import numpy as np

from ntq_jax.planners.ompl_checker import NumpyChecker
from ntq_jax.planners.ompl_worker import LOG_LEVELS, BridgeOutcome, worker_main
from ntq_jax.planners.options import bool_option, float_option, int_option, motion_check_option
from ntq_jax.planners.verify import finalize, valid_queries
from ntq_jax.types import PlanResult, PlanStatus

__all__ = ["plan_bitstar", "PLAN_STATUS", "BridgeOutcome", "query_seeds"]

#: The bridge's outcome -> the package's status. BIT* is anytime: no solution within
#: the budget proves nothing (TIMEOUT); a crash or a path that fails the package's
#: check leaves no verified path (NO_PATH).
PLAN_STATUS = {
    BridgeOutcome.EXACT: PlanStatus.SOLVED,
    BridgeOutcome.NOT_FOUND: PlanStatus.TIMEOUT,
    BridgeOutcome.BAD_QUERY: PlanStatus.INVALID,
    BridgeOutcome.CRASHED: PlanStatus.NO_PATH,
    BridgeOutcome.REJECTED: PlanStatus.NO_PATH,
}


def query_seeds(seed: int, n: int) -> np.ndarray:
    """The OMPL seed of each query: ``(n,)`` uint32 in ``[1, 2^31 - 1]``, from ``(seed, index)``."""
    out = np.empty(n, np.uint32)
    for i in range(n):
        v = np.random.SeedSequence([int(seed) & 0xFFFFFFFF, i]).generate_state(1)[0]
        out[i] = int(v) % 2147483646 + 1
    return out


def plan_bitstar(
    env,
    queries,
    *,
    padding: float | None = None,
    seed: int = 0,
    time_budget: float = 1.0,
    workers: int = 0,
    stop_on_first: bool = False,
    chunk_size: int | None = None,
    ompl_log_level: str = "error",
    hang_timeout: float | None = None,
    startup_timeout: float = 300.0,
    check: str = "discretized",
    keep_workers: bool = False,
    _crash_on: Mapping[int, int] | None = None,
) -> PlanResult:
    """Solves a batch of queries with OMPL's BIT* in parallel worker processes.

    Args:
        env: an :class:`ntq_jax.Env` with a rigid-body, n-link-arm or point robot (a
            serial arm: see below).
        queries: ``(N, 2, d)`` start and goal states.
        padding: clearance of the planning geometry (None: the environment's).
        seed: base seed; query ``i`` uses ``query_seeds(seed, N)[i]``.
        time_budget: seconds of BIT* per query (the paper: 3 s rigid-body data
            generation, 2 s evaluation; 2/4/6 s and 1/2/4 s for the 2/4/6-link arm).
        workers: worker processes; ``0`` = ``os.cpu_count()`` (never more than N).
        stop_on_first: stop at the first solution instead of using the whole budget.
        chunk_size: queries sent to a worker at a time (default: N / (4 workers), 1..8).
        ompl_log_level: OMPL's log level in the workers (``"error"`` by default;
            ``"warn"``, ``"info"``, ``"debug"``, ``"none"``).
        hang_timeout: a worker stuck on one query longer than this is killed and
            treated as crashed (default ``3 * time_budget + 30`` s).
        startup_timeout: seconds a new worker may take to import and get ready.
        check: the motion check of the final verification of BIT*'s paths (BIT*
            itself checks motions with our discretised check); see
            :func:`ntq_jax.robots.batch.motion_check`.
        keep_workers: keep the worker processes alive, idle, after the call, and
            reuse them in the next call with the same map, padding, budget and
            settings (in this process; idle workers of other settings are
            stopped). Saves a process start per call when one process plans many
            chunks (the Ray executor's tasks); the results do not depend on it.
        _crash_on: test hook, ``{query index: attempts}``: the worker calls
            ``os._exit`` when it starts that query on attempt ``< attempts``
            (``1`` = crash once, then solved on retry; ``2`` = CRASHED).

    Returns:
        A :class:`PlanResult` (statuses through :data:`PLAN_STATUS`). ``info`` holds
        ``bitstar_status`` ``(N,)`` int8 :class:`BridgeOutcome`, ``planner_costs``
        ``(N,)`` BIT*'s own float64 path length (inf unless found), ``solve_times``
        ``(N,)`` seconds in OMPL's ``solve``, ``seeds`` ``(N,)`` uint32, ``time_budget``,
        ``rejected`` (paths that failed the check), ``errors`` (query index ->
        traceback), ``workers`` (processes started), ``worker_deaths``,
        ``startup_time`` (slowest worker's seconds to get ready), ``n_valid_calls``
        and ``n_motion_calls`` (Python callbacks, summed) and ``wall_time``.

    A 3-D serial arm (the Panda) has no NumPy geometry for the workers: the
    registry's ``"bitstar"`` sends its queries to
    :func:`ntq_jax.planners.ompl_rrtconnect.plan_bitstar_jax` instead.

    Raises:
        TypeError, ValueError: malformed arguments (the message names the option);
            ImportError: ``ompl`` is not installed.
    """
    t_wall = time.perf_counter()
    q = _check_arguments(env, queries, time_budget, ompl_log_level)
    workers = int_option("bitstar", "workers", workers, 0) or (os.cpu_count() or 1)
    stop_on_first = bool_option("bitstar", "stop_on_first", stop_on_first)
    chunk_size = int_option("bitstar", "chunk_size", chunk_size, 1, none_ok=True)
    hang_timeout = float_option("bitstar", "hang_timeout", hang_timeout, none_ok=True)
    startup_timeout = float_option("bitstar", "startup_timeout", startup_timeout)
    check = motion_check_option("bitstar", check)
    keep_workers = bool_option("bitstar", "keep_workers", keep_workers)
    pad = env.resolve_padding(padding)
    n = q.shape[0]
    seeds = query_seeds(seed, n)
    results = _Results.empty(n)
    # Invalid queries are decided here, with the package's own kernel (OMPL only warns).
    ok = valid_queries(env, q, pad)
    results.outcome[~ok] = BridgeOutcome.BAD_QUERY
    todo = collections.deque(int(i) for i in np.flatnonzero(ok))
    if todo:
        checker = NumpyChecker(
            env.robot,
            np.asarray(env.world.bounds),
            np.asarray(env.world.boxes),
            np.asarray(env.world.discs),
            pad,
        )
        worker_args = (
            checker,
            float(time_budget),
            bool(stop_on_first),
            ompl_log_level,
            dict(_crash_on or {}),
        )
        hang = 3.0 * time_budget + 30.0 if hang_timeout is None else hang_timeout
        pool = _WorkerPool(
            worker_args,
            q,
            seeds,
            todo,
            min(workers, len(todo)),
            chunk_size,
            hang,
            startup_timeout,
            results,
            keep=keep_workers,
        )
        pool.run()
    res = _verified_result(env, q, pad, results, seeds, time_budget, check)
    res.info["wall_time"] = time.perf_counter() - t_wall
    return res


def _check_arguments(env, queries, time_budget, ompl_log_level) -> np.ndarray:
    """``queries`` as ``(N, 2, d)`` float32; ValueError / ImportError for what cannot run."""
    if env.robot.kind not in ("rigid_body", "nlink", "point"):
        raise ValueError(f"plan_bitstar: unsupported robot kind {env.robot.kind!r}")
    d = env.dim
    q = np.asarray(queries, np.float32)
    if q.ndim != 3 or q.shape[1:] != (2, d):
        raise ValueError(f"queries must have shape (N, 2, {d}) for {env.name}, got {q.shape}")
    float_option("bitstar", "time_budget", time_budget)  # seconds
    if ompl_log_level not in LOG_LEVELS:
        raise ValueError(f"ompl_log_level must be one of {LOG_LEVELS}, got {ompl_log_level!r}")
    if importlib.util.find_spec("ompl") is None:
        raise ImportError("plan_bitstar needs OMPL's Python bindings: pip install 'ompl>=2.0.1'")
    return q


@dataclasses.dataclass
class _Results:
    """What the workers report, per query (N queries), before verification."""

    outcome: np.ndarray  # (N,) int8 BridgeOutcome
    paths: list  # (L_i, d) float64 arrays, or None unless found
    planner_costs: np.ndarray  # (N,) float64
    solve_times: np.ndarray  # (N,) float64
    info: dict

    @classmethod
    def empty(cls, n: int) -> "_Results":
        info = {
            "workers": 0,
            "worker_deaths": 0,
            "startup_time": 0.0,
            "n_valid_calls": 0,
            "n_motion_calls": 0,
            "errors": {},
        }
        return cls(
            np.full(n, BridgeOutcome.NOT_FOUND, np.int8),
            [None] * n,
            np.full(n, np.inf),
            np.zeros(n),
            info,
        )


def _verified_result(
    env,
    q: np.ndarray,
    pad: float,
    r: _Results,
    seeds: np.ndarray,
    time_budget: float,
    check: str = "discretized",
) -> PlanResult:
    """The workers' raw paths verified by :func:`finalize`, statuses through PLAN_STATUS."""
    k, d = q.shape[0], q.shape[2]
    status = np.array([PLAN_STATUS[BridgeOutcome(o)] for o in r.outcome], np.int8)
    lengths = np.array(
        [
            len(p) if (p is not None and s == PlanStatus.SOLVED) else 0
            for p, s in zip(r.paths, status)
        ],
        np.int32,
    )
    paths = np.full((k, max(2, int(lengths.max(initial=0))), d), np.nan, np.float32)
    for i in np.flatnonzero(lengths):
        paths[i, : lengths[i]] = r.paths[i]
    info = dict(r.info)
    info.update(
        planner="bitstar",
        bitstar_status=r.outcome,
        solve_times=r.solve_times,
        planner_costs=r.planner_costs,
        seeds=seeds,
        time_budget=time_budget,
    )
    res = finalize(q, paths, lengths, status, info, env, pad, check)
    # a path BIT* found that fails the package's steer_to: finalize made it NO_PATH
    r.outcome[(r.outcome == BridgeOutcome.EXACT) & ~res.solved] = BridgeOutcome.REJECTED
    return res


_MAIN_LOCK = threading.Lock()

#: ``keep_workers``: idle worker processes by their pickled settings (one setting kept).
_IDLE: dict[bytes, list] = {}


def _stop_workers(workers) -> None:
    """Asks ``workers`` to stop, waits up to 5 s in all, then kills what is left."""
    for w in workers:
        try:
            w.conn.send(("stop",))
        except (OSError, ValueError):
            pass
    deadline = time.monotonic() + 5.0
    for w in workers:
        w.proc.join(timeout=max(0.0, deadline - time.monotonic()))
        w.kill()


@contextlib.contextmanager
def _main_hidden():
    """Starts worker processes without the caller's ``__main__`` module.

    ``spawn`` normally re-imports the parent's main script in every child (as
    ``__mp_main__``) before running the target: a script calling ``plan`` at
    top level without the ``if __name__ == "__main__":`` guard would then run
    again in each worker and die trying to start workers of its own. The
    preparation data multiprocessing sends the child names the main module
    found in ``sys.modules["__main__"]``; while a worker starts, that entry is a
    bare module with neither ``__file__`` nor ``__spec__`` (what an interactive
    session has), so the child imports nothing of the caller. The worker's
    target and arguments are all ``ntq_jax`` objects (the entry is restored at
    once, under a lock, and only :meth:`_Worker.__init__` holds it).
    """
    with _MAIN_LOCK:
        main = sys.modules.get("__main__")
        sys.modules["__main__"] = types.ModuleType("__main__")
        try:
            yield
        finally:
            if main is None:
                sys.modules.pop("__main__", None)
            else:
                sys.modules["__main__"] = main


class _Worker:
    """One worker process, its pipe and the queries it holds."""

    def __init__(self, ctx, args):
        parent, child = ctx.Pipe(duplex=True)
        self.conn = parent
        self.proc = ctx.Process(
            target=worker_main, args=(child,) + args, daemon=True, name="ntq_jax-bitstar"
        )
        with _main_hidden():
            self.proc.start()
        child.close()
        self.assigned: list[int] = []  # indices sent and not finished
        self.current: int | None = None  # started, not finished
        self.since = time.monotonic()  # start of the current query (or of the process)
        self.spawned = self.since
        self.ready = False

    def kill(self):
        if self.proc.is_alive():
            self.proc.kill()
        self.proc.join(timeout=5)
        self.conn.close()


class _WorkerPool:
    """The worker processes of one :func:`plan_bitstar` call, fed chunks of query indices.

    :meth:`run` returns when every query in ``todo`` has an outcome in ``results``.
    """

    def __init__(
        self,
        worker_args: tuple,
        q: np.ndarray,
        seeds: np.ndarray,
        todo: collections.deque,
        n_workers: int,
        chunk_size: int | None,
        hang_timeout: float,
        startup_timeout: float,
        results: _Results,
        keep: bool = False,
    ):
        if chunk_size is None:
            chunk_size = max(1, min(8, len(todo) // (4 * n_workers)))
        self.chunk_size = max(1, int(chunk_size))
        self.ctx = mp.get_context("spawn")
        self.worker_args = worker_args
        self.q, self.seeds, self.todo, self.results = q, seeds, todo, results
        self.info = results.info
        self.n_workers = n_workers
        self.hang_timeout, self.startup_timeout = hang_timeout, startup_timeout
        self.attempts = collections.Counter()  # crashes charged to each query
        self.remaining = set(todo)
        self.pool: list[_Worker] = []
        self.max_deaths = 2 * len(todo) + n_workers  # each death charges >= 1 query, each <= twice
        self.startup_failures = 0  # consecutive workers that died before getting ready
        self.keep = keep
        self.key = pickle.dumps(worker_args) if keep else b""

    def run(self) -> None:
        try:
            for _ in range(self.n_workers):
                self.spawn()
            while self.remaining:
                if self.startup_failures >= 3 or self.info["worker_deaths"] > self.max_deaths:
                    self._give_up()
                    break
                while len(self.pool) < min(self.n_workers, len(self.remaining)):
                    self.spawn()  # keep enough workers for the work left
                self._kill_stuck()
                self._poll(timeout=1.0)
                self._assign()
        finally:
            self.close()

    def spawn(self) -> _Worker:
        if self.keep:
            idle = _IDLE.get(self.key, [])
            while idle:
                w = idle.pop()
                if w.proc.is_alive():  # an idle worker of an earlier call: same settings
                    w.assigned, w.current, w.since = [], None, time.monotonic()
                    self.pool.append(w)
                    self.info["workers_reused"] = self.info.get("workers_reused", 0) + 1
                    return w
                w.kill()
        w = _Worker(self.ctx, self.worker_args)
        self.pool.append(w)
        self.info["workers"] += 1
        return w

    def feed(self, w: _Worker) -> None:
        """Sends an idle worker the next chunk of queries."""
        if w.assigned or not self.todo:
            return
        chunk = [self.todo.popleft() for _ in range(min(self.chunk_size, len(self.todo)))]
        w.assigned = list(chunk)
        w.since = time.monotonic()
        q, seeds, attempts = self.q, self.seeds, self.attempts
        try:
            w.conn.send(
                (
                    "task",
                    [
                        (i, q[i, 0].tolist(), q[i, 1].tolist(), int(seeds[i]), attempts[i])
                        for i in chunk
                    ],
                )
            )
        except OSError:  # the worker just died: its sentinel reports it next
            pass

    def finish(self, i: int, outcome: int) -> None:
        self.results.outcome[i] = outcome
        self.remaining.discard(i)

    def died(self, w: _Worker, why: str) -> None:
        """Charges a dead worker's current query (or its whole chunk) and re-queues the rest."""
        self.info["worker_deaths"] += 1
        w.kill()
        self.pool.remove(w)
        if not w.ready:
            self.startup_failures += 1
        blamed = [w.current] if w.current is not None else list(w.assigned)
        for i in blamed:
            self.attempts[i] += 1
            if self.attempts[i] >= 2:
                self.finish(i, BridgeOutcome.CRASHED)
                self.info["errors"].setdefault(i, why)
        for i in reversed(w.assigned):  # back to the front of the queue, in order
            if i in self.remaining:
                self.todo.appendleft(i)

    def close(self) -> None:
        if self.keep:
            for other in [k for k in _IDLE if k != self.key]:  # one setting's workers kept
                _stop_workers(_IDLE.pop(other))
            idle = _IDLE.setdefault(self.key, [])
            for w in list(self.pool):
                if (
                    w.ready
                    and not w.assigned
                    and w.current is None
                    and w.proc.is_alive()
                    and len(idle) < (os.cpu_count() or 1)
                ):
                    idle.append(w)
                    self.pool.remove(w)
        _stop_workers(self.pool)

    def _give_up(self) -> None:
        why = self.info["errors"].get("worker", "workers died before getting ready")
        warnings.warn(
            "plan_bitstar: BIT* workers cannot start; the remaining "
            f"{len(self.remaining)} queries are marked CRASHED:\n{why}",
            RuntimeWarning,
            stacklevel=4,
        )
        for i in list(self.remaining):
            self.finish(i, BridgeOutcome.CRASHED)

    def _kill_stuck(self) -> None:
        now = time.monotonic()
        for w in list(self.pool):
            limit = (
                self.startup_timeout
                if not w.ready
                else self.hang_timeout
                if w.assigned
                else math.inf
            )
            if now - w.since > limit:
                self.died(w, f"worker killed after {now - w.since:.0f} s without progress")

    def _poll(self, timeout: float) -> None:
        """Waits for messages or exits, handles everything a worker sent before its exit."""
        conns = {w.conn: w for w in self.pool}
        sentinels = {w.proc.sentinel: w for w in self.pool}
        for r in _mp_wait(list(conns) + list(sentinels), timeout=timeout):
            w = conns.get(r) or sentinels.get(r)
            if w not in self.pool:
                continue
            was_ready = w.ready
            try:
                while w.conn.poll():
                    self._handle(w, w.conn.recv())
            except (EOFError, OSError):
                pass
            if w.ready and not was_ready:
                self.startup_failures = 0
            if not w.proc.is_alive() or r in sentinels:
                w.proc.join(timeout=0.1)
                if w.proc.exitcode is not None or not w.proc.is_alive():
                    self.died(w, f"worker exited with code {w.proc.exitcode}")

    def _assign(self) -> None:
        """Every idle ready worker gets work (a death may have re-queued queries)."""
        for w in self.pool:
            w.assigned = [i for i in w.assigned if i in self.remaining]
        lost = self.remaining.difference(self.todo, *(w.assigned for w in self.pool))
        if lost:  # pragma: no cover (invariant: unfinished = queued or assigned)
            self.todo.extend(sorted(lost))
        for w in self.pool:
            if w.ready:
                self.feed(w)

    def _handle(self, w: _Worker, msg: tuple) -> None:
        """One message of :func:`ntq_jax.planners.ompl_worker.worker_main`."""
        kind, info = msg[0], self.info
        if kind == "ready":
            w.ready = True
            w.since = time.monotonic()
            info["startup_time"] = max(info["startup_time"], w.since - w.spawned)
        elif kind == "start":
            w.current = msg[1]
            w.since = time.monotonic()
        elif kind == "done":
            i, r = msg[1], msg[2]
            w.current = None
            w.since = time.monotonic()
            self.results.paths[i] = r["path"]
            self.results.planner_costs[i] = r["planner_cost"]
            self.results.solve_times[i] = r["solve_time"]
            info["n_valid_calls"] += r["n_valid"]
            info["n_motion_calls"] += r["n_motion"]
            self.finish(i, r["outcome"])
        elif kind == "error":
            i = msg[1]
            w.current = None
            info["errors"][i] = msg[2]
            warnings.warn(
                f"plan_bitstar: query {i} raised in the worker (status CRASHED):\n{msg[2]}",
                RuntimeWarning,
                stacklevel=5,
            )
            self.finish(i, BridgeOutcome.CRASHED)
        elif kind == "fatal":  # the worker could not start; it exits next
            info["errors"].setdefault("worker", msg[1])
