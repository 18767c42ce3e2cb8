import fcntl
import json
import os
import shutil
from pathlib import Path
from types import SimpleNamespace

import pytest

# Tests run on the CPU; keep XLA from grabbing every core's worth of threads twice.
os.environ.setdefault("JAX_PLATFORMS", "cpu")


def pytest_configure(config):
    """One JAX persistent compilation cache per test session, in a fresh temporary folder:
    the suite never reads or writes the user's cache (``~/.cache/ntq_jax/jax``, which the
    scripts' ``main`` turns on), so it runs alike on a developer's machine and a fresh
    clone; within the session the xdist workers and the subprocesses the tests start
    (they inherit the environment) share what one of them compiled, down to the
    smallest program.

    ``NTQ_TEST_JIT_CACHE=<folder>`` (a developer's opt-in, never set by the README's
    command or CI) keeps that cache in ``<folder>`` across runs instead: a run after the
    first compiles only the programs a change touched. JAX keys every entry on the
    program, the compile options, ``XLA_FLAGS`` and the JAX/jaxlib versions, so on the
    machine that filled it a kept cache is never stale, only larger."""
    if os.environ.get("PYTEST_XDIST_WORKER") is None:  # the controller (or a run without xdist)
        import tempfile

        kept = os.environ.get("NTQ_TEST_JIT_CACHE")
        if kept:
            os.makedirs(kept, exist_ok=True)
        folder = os.path.abspath(kept) if kept else tempfile.mkdtemp(prefix="ntq_jax_test_jit_")
        os.environ["JAX_COMPILATION_CACHE_DIR"] = folder
        # every program, however quick to compile: the workers and subprocesses share them
        os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0"
        config._ntq_jit_cache = None if kept else folder  # removed at the end unless kept
        import sys

        if "jax" in sys.modules:  # imported already (the profiler below): it read the old values
            import jax

            jax.config.update("jax_compilation_cache_dir", folder)
            jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)


_PROFILE = os.environ.get("NTQ_TEST_PROFILE")  # a folder: per-test compile times (see below)
_current = {"test": None}
_profile: dict = {}


if _PROFILE:
    import time

    import jax.monitoring

    def _on_duration(event, duration, fun_name=None, **_):
        if _current["test"] is not None and event.startswith("/jax/"):
            row = _profile.setdefault(_current["test"], {})
            key = event.rsplit("/", 1)[-1]
            row[key] = row.get(key, 0.0) + duration
            if key == "backend_compile_duration":
                row["compiles"] = row.get("compiles", 0) + 1
            if fun_name is not None:  # each program's name and its times
                row.setdefault("programs", []).append([key, str(fun_name), duration])

    jax.monitoring.register_event_duration_secs_listener(_on_duration)

    import logging

    class _CompileLog(logging.Handler):
        """Each lowering's module name and argument shapes (JAX logs them at DEBUG)."""

        def emit(self, record):
            if _current["test"] is not None and record.msg.startswith("Compiling %s with global"):
                name, avals = record.args[0], record.args[1]
                _profile.setdefault(_current["test"], {}).setdefault("lowered", []).append(
                    [str(name), " ".join(str(a) for a in avals)]
                )

    _pxla_log = logging.getLogger("jax._src.interpreters.pxla")
    _pxla_log.setLevel(logging.DEBUG)
    _pxla_log.addHandler(_CompileLog(logging.DEBUG))

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_protocol(item, nextitem):
        """With ``NTQ_TEST_PROFILE=<folder>``: each test's wall time and JAX compile
        times (trace, lowering, XLA backend; setup and teardown included) go to
        ``<folder>/<worker>.json`` for finding what the suite spends its time on."""
        _current["test"] = item.nodeid
        start = time.perf_counter()
        yield
        _profile.setdefault(item.nodeid, {})["wall"] = time.perf_counter() - start
        _current["test"] = None


#: Seconds each test file took in a profiled run (``NTQ_TEST_PROFILE``); refresh it by
#: copying the run's ``file_weights.json`` here. Only the order of the files uses it.
FILE_WEIGHTS = Path(__file__).with_name("file_weights.json")


def pytest_collection_modifyitems(session, config, items):
    """Heaviest files first (longest-processing-time order): with ``--dist loadfile`` and
    ``--no-loadscope-reorder`` the workers take whole files in this order, so the last
    files to start are the short ones and the workers finish close together. Files not in
    :data:`FILE_WEIGHTS` keep their place after the known ones; tests within a file keep
    theirs."""
    try:
        weights = json.loads(FILE_WEIGHTS.read_text())
    except (OSError, ValueError):
        return
    rank = {f: i for i, f in enumerate(sorted(weights, key=lambda f: -weights[f]))}
    items[:] = sorted(items, key=lambda it: rank.get(it.nodeid.split("::", 1)[0], len(rank)))


def _file_weights(folder: Path) -> dict:
    """Per-file wall seconds summed over the workers' profiles in ``folder``."""
    out: dict = {}
    for f in sorted(folder.glob("gw*.json")) + sorted(folder.glob("main.json")):
        for test, row in json.loads(f.read_text()).items():
            name = test.split("::", 1)[0]
            out[name] = round(out.get(name, 0.0) + row.get("wall", 0.0), 1)
    return dict(sorted(out.items(), key=lambda kv: -kv[1]))


def pytest_unconfigure(config):
    if _PROFILE and _profile:
        out = Path(_PROFILE)
        out.mkdir(parents=True, exist_ok=True)
        worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
        (out / f"{worker}.json").write_text(json.dumps(_profile, indent=1))
    if _PROFILE and os.environ.get("PYTEST_XDIST_WORKER") is None and Path(_PROFILE).is_dir():
        weights = _file_weights(Path(_PROFILE))  # the workers have written theirs by now
        (Path(_PROFILE) / "file_weights.json").write_text(json.dumps(weights, indent=1) + "\n")
    folder = getattr(config, "_ntq_jit_cache", None)
    if folder:
        shutil.rmtree(folder, ignore_errors=True)


_script_modules: dict = {}


@pytest.fixture
def script(capsys):
    """``script(name, *argv)``: ``scripts/<name>.py``'s ``main(argv)`` in this process, as
    ``SimpleNamespace(returncode, stdout, stderr)`` (captured with ``capsys``).

    The script's whole command line (argument parsing, its work, and ``run_cli``'s one
    ``error:`` line and exit code) without a new interpreter: no JAX import to pay, and the
    programs this worker compiled are reused. Every script is still started as a real
    subprocess by some test (what only a process shows: the ``__main__`` guard, stray
    output at import)."""
    from script_loader import load_script

    def run(name: str, *argv) -> SimpleNamespace:
        if name not in _script_modules:
            _script_modules[name] = load_script(name, f"_script_{name}")
        capsys.readouterr()  # drop what the test printed before
        code = _script_modules[name].main([str(a) for a in argv])
        out = capsys.readouterr()
        return SimpleNamespace(returncode=code, stdout=out.out, stderr=out.err)

    return run


#: The tiny point/2 pipeline run several files check (test_golden, test_train_all,
#: test_bad_inputs): data -> four PNets -> evaluation -> report, figures included.
TINY_RUN = [
    "envs=[point/2]",
    "data.k_train=40",
    "data.gamma_queries=2000",
    "data.gamma_eval=false",
    "train.epochs=2",
    "model.hidden=[32,32]",
    "eval.k_test=16",
    "eval.n_plan=20",
    "eval.replan_rounds=2",
    "eval.replan_steps=6",
    "eval.gamma_queries=2000",
]


def _produce_tiny_run(out: Path) -> dict:
    from ntq_jax.experiment.pipeline import load_config, prepare_run, run_pipeline

    cfg = load_config(None, TINY_RUN)
    written = run_pipeline(cfg, prepare_run(cfg, out), progress=False, log=lambda _: None)
    return {k: str(Path(v).relative_to(out)) for k, v in written.items()}


@pytest.fixture(scope="session")
def tiny_run(tmp_path_factory):
    """One finished run of :data:`TINY_RUN` (``run_pipeline(cfg, prepare_run(cfg, out),
    progress=False)``): ``.path`` its folder, ``.written`` the files run_pipeline returned,
    ``.config`` the ``--set`` list (a test asserts it is the config it means).

    Taken once per test session: under xdist the first worker that needs it runs the
    pipeline (the others wait on a lock and read its folder). READ ONLY: a test that
    changes a run works on a copy (``shutil.copytree``).
    """
    if os.environ.get("PYTEST_XDIST_WORKER") is None:
        root = tmp_path_factory.mktemp("tiny_run")
    else:  # the folder all workers of this session share
        root = tmp_path_factory.getbasetemp().parent / "tiny_run"
        root.mkdir(exist_ok=True)
    run, done = root / "run", root / "written.json"
    with open(root / "lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not done.is_file():
            shutil.rmtree(run, ignore_errors=True)  # a worker's failed attempt
            done.write_text(json.dumps(_produce_tiny_run(run)))
    written = {k: run / v for k, v in json.loads(done.read_text()).items()}
    return SimpleNamespace(path=run, written=written, config=list(TINY_RUN))
