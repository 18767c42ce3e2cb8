"""Where the host-side planning chunks run: in this process (``local``) or as Ray tasks (``ray``).

An executor is a small strategy injected into the stages that plan in chunks
(:func:`ntq_jax.planners.jobs.plan_pool`, the evaluation's reference planning,
:mod:`ntq_jax.experiment.pipeline`'s per-environment data stage). The compute code stays
free of executor knowledge: a chunk is a pure function of its arguments
(environment, queries, planner and options, padding, the chunk's seed) that
returns arrays; the DRIVER writes each chunk's result atomically into the run
folder as it arrives, so the run folder stays the single source of truth and a
run can be resumed with either executor.

* :class:`LocalExecutor` (``executor: local``, the default): every chunk runs in
  this process, one after the other (BIT* still uses its own worker processes,
  ``planner.workers``).
* :class:`RayExecutor` (``executor: ray``): every chunk is a Ray task
  (``num_cpus`` per task, default 1), retried by Ray up to ``max_retries``
  times when its worker process dies (``ray.remote(max_retries=...)``). A
  retried task gets the same arguments, so the same planner seed: the chunk's
  seed is derived from its position in the pool (``planning.chunk_seed``),
  never from the attempt or the worker. Results come back in completion order
  (``ray.wait``) and the driver writes each once. ``address=None`` starts a
  local Ray instance; ``"auto"`` joins the running cluster (``ray start``).

Only the driver writes chunk files. The one thing a task writes itself is the
``roadmap`` planner's on-disk roadmap cache (``<run>/data/<env>/roadmap``,
written atomically): on a cluster the run folder must therefore be on a path
every node sees (NFS or similar, same path on every node), or each node builds
its own copy of the roadmap.

Usage::

    from ntq_jax.executors import make_executor
    ex = make_executor("ray", address="auto")
    for i, result in ex.imap_unordered(fn, [(a, b), (c, d)]):
        ...  # result of fn(*items[i])
"""

from __future__ import annotations

import os
import socket
import sys
import threading
import time
import warnings
from typing import Any, Callable, Iterable, Iterator, Protocol, Sequence

__all__ = [
    "EXECUTORS",
    "Executor",
    "LocalExecutor",
    "RayExecutor",
    "make_executor",
    "worker_env",
    "RAY_MISSING",
]

EXECUTORS = ("local", "ray")
_INIT_LOCK = threading.Lock()  # threads of one driver share one Ray connection
RAY_MISSING = "the ray executor needs Ray: pip install -e '.[ray]' (or pip install 'ray>=2.40')"


class Executor(Protocol):
    """Runs independent calls ``fn(*args)``; the results come back as ``(index, result)``."""

    name: str

    @property
    def slots(self) -> int:
        """How many calls run at the same time (1 for the local executor)."""

    def imap_unordered(self, fn: Callable, items: Sequence[tuple]) -> Iterator[tuple[int, Any]]:
        """``(i, fn(*items[i]))`` for every item, in completion order."""

    def adapt_planner(self, plan_fn: Callable) -> Callable:
        """The planner callable a task runs (e.g. BIT* with one worker per task CPU)."""

    def start(self) -> None:
        """Starts or joins the executor's resources now (call it from the main thread)."""


class LocalExecutor:
    """Today's behaviour: every call in this process, in order."""

    name = "local"
    slots = 1

    def imap_unordered(self, fn: Callable, items: Sequence[tuple]) -> Iterator[tuple[int, Any]]:
        for i, args in enumerate(items):
            yield i, fn(*args)

    def adapt_planner(self, plan_fn: Callable) -> Callable:
        return plan_fn

    def start(self) -> None:
        pass

    def __repr__(self) -> str:
        return "LocalExecutor()"


def _import_ray():
    try:
        import ray
    except ImportError:
        from ntq_jax.errors import UsageError

        raise UsageError(RAY_MISSING) from None
    return ray


RAY_CONNECT_TIMEOUT = 3.0  # seconds to reach a cluster's head before it is called unreachable


def _ray_current_cluster() -> str | None:
    """The address ``ray start --head`` left for ``auto`` on this machine (Ray's own lookup:
    ``RAY_ADDRESS``, then ``<tmp>/ray/ray_current_cluster``), or None."""
    import tempfile

    env = os.environ.get("RAY_ADDRESS")
    if env:
        return env
    for root in {tempfile.gettempdir(), "/tmp"}:
        f = os.path.join(root, "ray", "ray_current_cluster")
        try:
            with open(f) as fh:
                text = fh.read().strip()
        except OSError:
            continue
        if text:
            return text
    return None


def check_ray_address(address: str, timeout: float = RAY_CONNECT_TIMEOUT) -> None:
    """Raises a ``UsageError`` naming ``address`` unless a Ray head answers there.

    ``address`` is ``auto`` (the cluster ``ray start --head`` started on this machine),
    ``<host>:<port>`` or ``ray://<host>:<port>`` (Ray Client). The head's port must
    accept a TCP connection within ``timeout`` seconds; nothing else is started.
    """
    from ntq_jax.errors import UsageError

    fix = (
        "start one with 'ray start --head' (then --ray-address auto), pass the head "
        "node's <host>:<port>, or leave --ray-address out to start a local Ray instance"
    )
    given = address
    if address == "auto":
        found = _ray_current_cluster()
        if found is None:
            raise UsageError(
                f"--ray-address auto: no Ray cluster is running on this machine; {fix}"
            )
        address = found
    target = address.split("://", 1)[1] if "://" in address else address
    host, sep, port = target.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise UsageError(
            f"--ray-address {given!r}: expected auto, <host>:<port> or ray://<host>:<port>; {fix}"
        )
    try:
        conn = socket.create_connection((host.strip("[]"), int(port)), timeout=timeout)
    except OSError as e:
        why = "timed out" if isinstance(e, TimeoutError) else (e.strerror or type(e).__name__)
        raise UsageError(
            f"--ray-address {given}: no Ray cluster answers at {host}:{port} "
            f"({why} after at most {timeout:g} s); {fix}"
        ) from None
    with conn:
        why = None if _tls() else _not_grpc(conn, timeout)
    if why:
        raise UsageError(
            f"--ray-address {given}: {host}:{port} answers but is not a Ray "
            f"cluster's head ({why}); {fix}"
        )


#: HTTP/2's client connection preface and an empty SETTINGS frame (RFC 9113, 3.4)
_H2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])


def _tls() -> bool:
    """Whether Ray's gRPC connections use TLS here (``RAY_USE_TLS``): then not probed."""
    return os.environ.get("RAY_USE_TLS", "0").strip().lower() in ("1", "true", "yes")


def _not_grpc(conn: socket.socket, timeout: float) -> str | None:
    """Why the server on ``conn`` is not a gRPC server (as a Ray head's GCS or Ray Client
    server is), or None: a gRPC server answers the HTTP/2 preface with its SETTINGS frame
    at once; anything else (an HTTP/1 answer, a closed connection, silence for ``timeout``
    seconds) is not one. Bounded: at most ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    got, closed = b"", False
    try:
        conn.sendall(_H2_PREFACE)
        while len(got) < 9 and not closed and time.monotonic() < deadline:
            conn.settimeout(max(deadline - time.monotonic(), 0.01))
            part = conn.recv(9 - len(got))
            got, closed = got + part, not part
    except TimeoutError:
        pass
    except (ConnectionResetError, BrokenPipeError):
        closed = True
    except OSError as e:
        return f"the connection failed: {e.strerror or type(e).__name__}"
    if len(got) == 9 and got[3] == 4:  # a frame header of type SETTINGS
        return None
    if not got:
        return (
            "it closed the connection"
            if closed
            else f"no answer to a gRPC connection within {timeout:g} s"
        )
    text = got.split(b"\r")[0].decode("ascii", "replace")
    return f"it answered {text!r}, not gRPC" if text.isprintable() else "it does not speak gRPC"


class RayExecutor:
    """Every call a Ray task with ``num_cpus`` CPUs, retried ``max_retries`` times on worker death.

    Args:
        address: ``None`` starts a local Ray instance (``num_cpus`` CPUs for it:
            ``local_cpus``); ``"auto"`` or ``"<host>:<port>"`` joins a cluster.
            When Ray is already initialised in this process it is used as it is.
        num_cpus: CPUs each task reserves (BIT* runs that many worker processes
            in a task).
        max_retries: Ray's ``max_retries``: re-executions of a task whose worker died.
        local_cpus: CPUs of a local instance started here (None: every core).
    """

    name = "ray"

    def __init__(
        self,
        address: str | None = None,
        *,
        num_cpus: int = 1,
        max_retries: int = 3,
        local_cpus: int | None = None,
    ):
        self.address = address
        self.num_cpus = int(num_cpus)
        self.max_retries = int(max_retries)
        self.local_cpus = local_cpus
        self._ray = None
        _import_ray()  # a missing Ray is an error before any work (Ray starts at the first task)
        if address is not None:
            check_ray_address(address)  # an unreachable cluster is an error now, in seconds
        self._task = None
        self.latencies: list[float] = []  # per task: seconds from submission to its start
        self.task_seconds: list[float] = []  # per task: seconds of fn(*args) in the worker

    # -- Ray ------------------------------------------------------------------
    def start(self) -> None:
        """Starts (or joins) Ray now; the scripts call it in the main thread before their
        per-environment threads (Ray installs its signal handlers there)."""
        self.ray()

    def ray(self):
        """The ``ray`` module, initialised (lazily: nothing is started before the first task)."""
        with _INIT_LOCK:
            return self._init()

    def _init(self):
        if self._ray is None:
            ray = _import_ray()
            if not ray.is_initialized():
                kw: dict = {
                    "include_dashboard": False,
                    "log_to_driver": True,
                    "configure_logging": False,
                }
                if self.address is None:
                    kw["num_cpus"] = self.local_cpus
                kw["runtime_env"] = {"env_vars": worker_env(local=self.address is None)}
                with warnings.catch_warnings():  # Ray's fork+exec of its own daemons
                    warnings.filterwarnings("ignore", message=r"os\.fork\(\) was called")
                    ray.init(address=self.address, **kw)
            self._ray = ray
        return self._ray

    @property
    def slots(self) -> int:
        cpus = self.ray().cluster_resources().get("CPU", 1)
        return max(1, int(cpus // max(self.num_cpus, 1)))

    def submit(self, fn: Callable, *args):
        """One task ``fn(*args)``: an ``ObjectRef`` of :func:`_timed_call`'s triple."""
        if self._task is None:
            self._task = self.ray().remote(num_cpus=self.num_cpus, max_retries=self.max_retries)(
                _timed_call
            )
        return self._task.remote(fn, time.time(), *args)

    def imap_unordered(self, fn: Callable, items: Sequence[tuple]) -> Iterator[tuple[int, Any]]:
        ray = self.ray()
        refs = {self.submit(fn, *args): i for i, args in enumerate(items)}
        pending = list(refs)
        try:
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                for ref in done:
                    latency, seconds, result = ray.get(ref)
                    self.latencies.append(latency)
                    self.task_seconds.append(seconds)
                    yield refs[ref], result
        finally:
            for ref in pending:  # the caller stopped early (an error, Ctrl-C)
                ray.cancel(ref, force=True)

    def adapt_planner(self, plan_fn: Callable) -> Callable:
        with_options = getattr(plan_fn, "with_options", None)
        if with_options is not None and getattr(plan_fn, "name", None) == "bitstar":
            # the task's CPUs, not the node's; its BIT* processes kept for its next chunks
            return with_options(workers=self.num_cpus, keep_workers=True)
        return plan_fn

    def __repr__(self) -> str:
        return (
            f"RayExecutor(address={self.address!r}, num_cpus={self.num_cpus}, "
            f"max_retries={self.max_retries})"
        )


def worker_env(*, local: bool) -> dict[str, str]:
    """The environment variables of the Ray instance's worker processes.

    ``JAX_PLATFORMS=cpu``: the tasks are host-side work, never on a GPU of the node
    (each worker process would otherwise reserve most of its memory). On a local
    instance (``local``), also this process's persistent compilation cache when it is
    on (``JAX_COMPILATION_CACHE_DIR`` and ``JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS``,
    e.g. from :func:`ntq_jax.artifacts.enable_compile_cache`): the workers then load
    the programs compiled here, by each other and by earlier runs instead of each
    compiling every one. A cluster's nodes keep their own settings (the folder is a
    path on this machine).
    """
    env = {"JAX_PLATFORMS": "cpu"}
    if local and "jax" in sys.modules:
        import jax

        folder = jax.config.jax_compilation_cache_dir
        if folder and jax.config.jax_enable_compilation_cache:
            env["JAX_COMPILATION_CACHE_DIR"] = str(folder)
            env["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = repr(
                float(jax.config.jax_persistent_cache_min_compile_time_secs)
            )
    return env


def _timed_call(fn: Callable, submitted: float, *args):
    """The task body: ``(seconds from submission to start, seconds of fn, fn(*args))``."""
    started = time.time()
    t0 = time.perf_counter()
    out = fn(*args)
    return started - submitted, time.perf_counter() - t0, out


def make_executor(name: str | None = "local", address: str | None = None, **kwargs) -> Executor:
    """``local`` (default) or ``ray`` (``address``: None = a local instance, ``auto`` = a cluster)."""
    name = name or "local"
    if name == "local":
        return LocalExecutor()
    if name == "ray":
        return RayExecutor(address, **kwargs)
    raise ValueError(f"executor must be one of {', '.join(EXECUTORS)}, got {name!r}")


def run_all(executor: Executor, fn: Callable, items: Iterable[tuple]) -> list:
    """Every ``fn(*item)`` through ``executor``, in item order."""
    items = list(items)
    out: list = [None] * len(items)
    for i, r in executor.imap_unordered(fn, items):
        out[i] = r
    return out
