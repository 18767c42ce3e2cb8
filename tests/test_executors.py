"""The executors (ntq_jax.executors): local and Ray give the same bytes, Ray survives a killed
worker without writing a chunk twice, and a run started locally resumes under Ray.

The Ray tests run on one local Ray instance (2 CPUs, no dashboard) shared by the module.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import threading
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from ntq_jax import data, make_env
from ntq_jax.executors import LocalExecutor, RayExecutor, make_executor, worker_env
from ntq_jax.experiment import config as C
from ntq_jax.planners import jobs as planning

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "scripts"))

ENV = "point/2"
SETS = ["data.k_train=40", "data.chunk=10", "data.gamma_queries=5000", "data.gamma_eval=false"]
ARGS = ["--no-progress", "--no-figure"] + [a for s in SETS for a in ("--set", s)]
ENVS = ["--env", ENV, "--env", "point/3"]  # two maps: generated concurrently under Ray


def _cfg(*extra: str) -> C.Config:
    return C.load(None, SETS + list(extra))


def _files(env_dir: Path) -> dict[str, bytes]:
    """Every dataset file and env.json, by relative path."""
    out = {
        p.relative_to(env_dir).as_posix(): p.read_bytes()
        for p in sorted(env_dir.glob("D*/*"))
        if p.is_file()
    }
    out["env.json"] = (env_dir / "env.json").read_bytes()
    return out


@pytest.fixture(scope="module")
def ray_session():
    ray = pytest.importorskip("ray")
    with warnings.catch_warnings():  # Ray's fork+exec of its own daemons
        warnings.filterwarnings("ignore", message=r"os\.fork\(\) was called")
        ray.init(
            num_cpus=2,
            include_dashboard=False,
            configure_logging=False,
            runtime_env={"env_vars": worker_env(local=True)},
        )
    yield ray
    ray.shutdown()


@pytest.fixture(scope="module")
def local_run(tmp_path_factory):
    """generate_data.py --executor local: the reference bytes, per map folder."""
    import generate_data

    out = tmp_path_factory.mktemp("local")
    assert generate_data.main(ARGS + ENVS + ["--out", str(out), "--executor", "local"]) == 0
    return {slug: _files(out / slug) for slug in ("point_2", "point_3")}


@pytest.fixture
def writes(monkeypatch):
    """Every chunk file the driver writes, in order (planning.chunk_written)."""
    got: list[str] = []
    monkeypatch.setattr(planning, "chunk_written", lambda p: got.append(p.name))
    return got


# ---------------------------------------------------------------------------
# No Ray needed
# ---------------------------------------------------------------------------


def test_config_keys_are_validated_and_left_out_of_the_hash():
    base = C.load(None)
    ray_cfg = C.load(None, ["executor=ray", "ray_address=auto"])
    assert ray_cfg.hash() == base.hash()  # a run folder resumes under either executor
    assert "executor" not in base.to_dict() and ray_cfg.to_dict()["executor"] == "ray"
    with pytest.raises(C.ConfigError, match=r"executor: must be local or ray"):
        C.load(None, ["executor=dask"])
    with pytest.raises(ValueError, match="executor must be one of"):
        make_executor("dask")
    assert isinstance(make_executor(None), LocalExecutor)


def test_ray_address_needs_the_ray_executor(capsys):
    import generate_data

    assert (
        generate_data.main(ARGS + ["--env", ENV, "--out", "/nonexistent", "--ray-address", "auto"])
        == 2
    )
    assert "--ray-address needs --executor ray" in capsys.readouterr().err


def test_missing_ray_is_one_line(monkeypatch, capsys):
    import generate_data

    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError
    assert (
        generate_data.main(ARGS + ["--env", ENV, "--out", "/tmp/unused", "--executor", "ray"]) == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        "error: the ray executor needs Ray: pip install -e '.[ray]' (or pip install 'ray>=2.40')"
    ]


def test_local_workers_get_this_process_compilation_cache():
    """A local instance's workers are told this process's cache folder and threshold (read
    from jax.config, where enable_compile_cache puts them, not only inherited through the
    environment); a cluster's nodes are not, and with the cache off there is nothing to pass.
    (The suite's own cache is on: tests/conftest.py.)"""
    import jax

    folder = jax.config.jax_compilation_cache_dir
    assert folder, "the suite runs with a compilation cache"
    assert worker_env(local=True) == {
        "JAX_PLATFORMS": "cpu",
        "JAX_COMPILATION_CACHE_DIR": folder,
        "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": repr(
            float(jax.config.jax_persistent_cache_min_compile_time_secs)
        ),
    }
    assert worker_env(local=False) == {"JAX_PLATFORMS": "cpu"}
    jax.config.update("jax_enable_compilation_cache", False)  # nothing compiles meanwhile
    try:
        assert worker_env(local=True) == {"JAX_PLATFORMS": "cpu"}
    finally:
        jax.config.update("jax_enable_compilation_cache", True)


# ---------------------------------------------------------------------------
# Ray
# ---------------------------------------------------------------------------


def test_generate_data_ray_is_byte_identical_to_local(ray_session, local_run, tmp_path, writes):
    import generate_data

    assert generate_data.main(ARGS + ENVS + ["--out", str(tmp_path), "--executor", "ray"]) == 0
    for slug, want in local_run.items():
        got = _files(tmp_path / slug)
        assert got.keys() == want.keys() and len(got) > 30
        for k in got:
            assert got[k] == want[k], (slug, k)
    assert len(writes) == 16  # per map, 80 pooled queries in chunks of 10: each written once
    assert len(set(writes)) == 8  # (the two maps' chunk files have the same names)


def _task_workers() -> list[int]:
    """Pids of this process's Ray workers that are running a task (title ``ray::_timed_call``)."""
    me, found = os.getpid(), []
    for p in os.listdir("/proc"):
        if not p.isdigit():
            continue
        try:
            title = Path(f"/proc/{p}/cmdline").read_bytes().split(b"\0")[0]
            if not title.startswith(b"ray::_timed_call"):
                continue
            q = int(p)
            while q > 1 and q != me:  # a descendant of this process (our Ray instance) only
                q = int(Path(f"/proc/{q}/stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue
        if q == me:
            found.append(int(p))
    return found


def test_killed_worker_is_retried_with_identical_output(ray_session, local_run, tmp_path, writes):
    """Chunks of 2 (40 tasks, a new shape to compile in each worker: a wide window to catch a
    worker running one); A* does not depend on the chunking, so the arrays are local_run's."""
    ex = RayExecutor()
    out: dict = {}

    def run():
        try:
            opts = C.data_options(_cfg("data.chunk=2"), ENV)
            out["summary"] = data.generate_datasets(
                make_env(ENV),
                opts,
                tmp_path,
                env_name=ENV,
                progress=False,
                figure=False,
                executor=ex,
            )
        except BaseException as e:  # noqa: BLE001 (reported below)
            out["error"] = e

    t = threading.Thread(target=run)
    t.start()
    killed = None
    deadline = time.time() + 60
    while killed is None and t.is_alive() and time.time() < deadline:
        pids = _task_workers()
        if pids:
            killed = pids[0]
            os.kill(killed, signal.SIGKILL)
        time.sleep(0.01)
    t.join(900)  # generous: the machine may be loaded (a slow run is not a failure here)
    assert not t.is_alive() and "error" not in out, out.get("error")
    assert killed is not None, "no Ray worker was seen running a chunk"
    got, want = _files(tmp_path / "point_2"), local_run["point_2"]
    assert got.keys() == want.keys()
    for k in got:  # byte for byte; meta.json records the config's hash, which has data.chunk
        if k.endswith("meta.json"):
            a, b = json.loads(got[k]), json.loads(want[k])
            assert a.pop("config_hash") != b.pop("config_hash") and a == b, k
        else:
            assert got[k] == want[k], k
    assert len(writes) == len(set(writes)) == 40  # every chunk written once, none lost
    assert out["summary"]["planned_queries"] == 80 and out["summary"]["reused_queries"] == 0


def test_local_run_interrupted_then_resumed_with_ray(ray_session, local_run, tmp_path, monkeypatch):
    written: list[str] = []

    def stop_after_three(p):
        written.append(p.name)
        if len(written) == 3:
            raise KeyboardInterrupt  # as Ctrl-C after the third chunk was written

    monkeypatch.setattr(planning, "chunk_written", stop_after_three)
    with pytest.raises(KeyboardInterrupt):
        data.generate_datasets(
            make_env(ENV),
            C.data_options(_cfg(), ENV),
            tmp_path,
            env_name=ENV,
            progress=False,
            figure=False,
            executor=LocalExecutor(),
        )
    assert not (tmp_path / "point_2" / "D0" / "meta.json").exists()
    first = list(written)
    monkeypatch.setattr(planning, "chunk_written", written.append)
    s = data.generate_datasets(
        make_env(ENV),
        C.data_options(_cfg("executor=ray"), ENV),
        tmp_path,
        env_name=ENV,
        progress=False,
        figure=False,
        executor=RayExecutor(),
    )
    assert s["reused_queries"] == 30 and not s["skipped"]
    assert len(written) == len(set(written)) == 8 and set(first) <= set(written[:3])
    assert _files(tmp_path / "point_2") == local_run["point_2"]


def test_reference_roadmap_chunks_match_local(ray_session, tmp_path):
    """The evaluation's reference, roadmap on point/2: chunk tasks (first one alone, which
    builds the roadmap) give the single local call's paths and costs."""
    from ntq_jax.experiment.references import reference_plans, test_queries

    cfg = C.load(
        None,
        [
            "envs=[point/2]",
            "planner.name=roadmap",
            "planner.milestones=200",
            "planner.grow_rounds=0",
            "eval.k_test=8",
            "data.chunk=4",
        ],
    )
    env = make_env("point/2")
    got = {}
    for name, ex in (("local", LocalExecutor()), ("ray", RayExecutor())):
        out = tmp_path / name
        q = test_queries(env, cfg, "point_2", out)
        got[name] = reference_plans(env, cfg, "point/2", "point_2", q, out, None, ex)
        assert not (out / ".work").exists()
        assert len(list((out / "roadmap").glob("roadmap_*.npz"))) == 1  # built once
    a, b = got["local"], got["ray"]
    for kind in ("uniform", "nontrivial"):
        for f in ("costs", "status", "lengths"):
            np.testing.assert_array_equal(a[f"{kind}_{f}"], b[f"{kind}_{f}"])
        w = int(a[f"{kind}_lengths"].max())
        np.testing.assert_array_equal(a[f"{kind}_paths"][:, :w], b[f"{kind}_paths"][:, :w])
    assert json.dumps(str(a["planner"])) == json.dumps(str(b["planner"]))


@pytest.mark.parametrize(
    "address, words",
    [
        ("127.0.0.1:1", ["127.0.0.1:1", "no Ray cluster answers"]),
        ("not-an-address", ["not-an-address", "expected auto"]),
        ("host:99999", ["host:99999", "expected auto"]),
        ("auto", ["auto", "no Ray cluster is running"]),
    ],
)
def test_an_unreachable_ray_cluster_is_one_line_in_seconds_before_anything_is_written(
    address, words, tmp_path, capsys, monkeypatch
):
    """--ray-address that cannot be reached: exit 2 within seconds, one error line naming
    the address, no run folder (the probe's 127.0.0.1:1 hung for minutes)."""
    pytest.importorskip("ray")
    import importlib.util
    import time
    from pathlib import Path

    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))  # no ray_current_cluster there
    import ntq_jax.executors as X

    if address == "auto" and X._ray_current_cluster() is not None:
        pytest.skip("a Ray cluster is running on this machine")
    root = Path(__file__).resolve().parents[1]
    spec = importlib.util.spec_from_file_location("train_all", root / "scripts" / "train_all.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    out = tmp_path / "run"
    t0 = time.perf_counter()
    assert mod.main(["--executor", "ray", "--ray-address", address, "--out", str(out)]) == 2
    assert time.perf_counter() - t0 < 30
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and all(w in err[0] for w in words)
    assert not out.exists()


def _serve(answer):
    """A TCP server on 127.0.0.1 that answers each connection with ``answer(conn)``; its port."""
    import socket

    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen()

    def loop():
        while True:
            conn, _ = srv.accept()
            with conn:
                answer(conn)

    threading.Thread(target=loop, daemon=True).start()
    return srv.getsockname()[1]


def test_a_port_that_answers_but_is_not_ray_is_one_line_in_seconds(tmp_path, capsys, monkeypatch):
    """An HTTP server at --ray-address hung ray.init for minutes (and a dropped connection
    was a traceback after 27 s), leaving config.yaml and run.json behind: a Ray head is a
    gRPC server, which answers HTTP/2's preface with its SETTINGS frame at once."""
    pytest.importorskip("ray")
    import http.server

    from ntq_jax.errors import UsageError
    from ntq_jax.executors import check_ray_address

    class Quiet(http.server.SimpleHTTPRequestHandler):
        def log_message(self, *args):
            pass

    http_server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Quiet)
    threading.Thread(target=http_server.serve_forever, daemon=True).start()
    import train_all

    out = tmp_path / "run"
    t0 = time.perf_counter()
    address = f"127.0.0.1:{http_server.server_address[1]}"
    assert train_all.main(["--executor", "ray", "--ray-address", address, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and address in err[0] and "not a Ray cluster's head" in err[0], err
    assert time.perf_counter() - t0 < 30 and not out.exists()
    import reproduce  # it made its run folder before the check

    assert (
        reproduce.main(
            [
                "--config",
                "configs/point_small.yaml",
                "--env",
                "point/2",
                "--executor",
                "ray",
                "--ray-address",
                address,
                "--runs",
                str(tmp_path / "runs"),
                "--results",
                str(tmp_path / "res"),
            ]
        )
        == 2
    )
    assert "not a Ray cluster's head" in capsys.readouterr().err
    assert not (tmp_path / "runs" / "point").exists()
    http_server.shutdown()
    for answer, words in (
        (lambda c: None, "closed the connection"),
        (lambda c: time.sleep(2), "no answer"),
    ):
        with pytest.raises(UsageError, match=words):
            check_ray_address(f"127.0.0.1:{_serve(answer)}", timeout=0.5)
    settings = bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])  # a gRPC server's first frame
    check_ray_address(f"127.0.0.1:{_serve(lambda c: (c.sendall(settings), c.recv(64)))}")


def test_a_ray_head_passes_the_address_check(ray_session):
    from ntq_jax.executors import check_ray_address

    check_ray_address(ray_session.get_runtime_context().gcs_address)
