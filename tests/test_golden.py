"""Golden record: a tiny pipeline and an arm data run, fingerprinted, against ``tests/golden.json``.

The run: point/2 (grid A* data, four PNets, neural planning, report) and the data
of the 2-link arm (grid A* in joint space). Its outputs are held to the record in
three parts, each as strictly as the computation allows across machines:

``portable`` (bit for bit on every machine of the record's data class)
    The bytes of every dataset array (queries, planned paths, samples) of both
    runs. Their floats come from compiled code too (query sampling, collision
    checks), but from elementwise arithmetic whose rounding is fixed by IEEE
    once the compiler's choice to fuse a multiply and an add (FMA) is fixed:
    the data class is ``<arch>-fma`` or ``<arch>-nofma``
    (:func:`data_class`). Measured on x86_64: XLA told to use 128-, 256- or
    512-bit vectors, AVX2 or AVX-512, or fast math gives the same bytes;
    without FMA (``--xla_cpu_max_isa=AVX``) the arm's queries differ
    (``minval + u * (maxval - minval)`` is rounded once with an FMA, twice
    without). A machine of another class takes its own record (below).

``params`` (within :data:`PARAMS_ATOL` on every machine whose datasets matched)
    The trained parameters of the four PNets against ``tests/golden_params.npz``.
    Training is compiled float code whose reduction order and vector width
    depend on the CPU XLA compiles for, so its bits are not portable. Measured
    on the golden run's 2-epoch training (max |difference| over all
    parameters, parameters of magnitude <= 1.2): other vector widths <= 6e-8,
    fast math 1.0e-6, no FMA 1.9e-6; one training input changed in its
    exponent byte moves them by 2.4e-2. ``PARAMS_ATOL = 1e-4`` sits 50x
    above the first and 240x below the second (a change of one input's last
    mantissa bit, 6e-8, is below any tolerance: the ``portable`` part catches
    it). ``test_golden_check_under_foreign_codegen`` re-measures both sides.

``machine`` (bit for bit against the record of this machine's numerics)
    The parameters' bits, every saved planned path and every number of
    ``results.json`` but wall-clock times. Downstream of trained floats, these
    can move on another CPU (a success that flips with a last-bit change of a
    parameter), so they are recorded per numerics fingerprint
    (:func:`numerics_fingerprint`: JAX and jaxlib versions, the CPU's vendor,
    model and vector/FMA features, ``XLA_FLAGS``). ``golden.json`` holds the
    records of the machines it was taken on; on a machine with a new
    fingerprint the test takes a local record (``tests/.golden_local.json``,
    not committed) and passes with a warning, and every later run on that
    machine is compared with it bit for bit. A local record is tied to the
    ``golden.json`` it was taken beside: a new ``golden.json`` (a deliberate
    change of results) makes it be taken again.

A refactor proves itself bit for bit on one machine::

    python tests/test_golden.py --record-local   # before the refactor: this machine, this code
    ... refactor ...
    python -m pytest tests/test_golden.py        # every part compared, bit for bit

A deliberate change of results re-records everything (the portable part, the
parameters and this machine's record; the other machines' records are
dropped, being stale)::

    python tests/test_golden.py --record
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import re
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
from conftest import TINY_RUN

ROOT = Path(__file__).resolve().parents[1]
GOLDEN = ROOT / "tests" / "golden.json"
GOLDEN_PARAMS = ROOT / "tests" / "golden_params.npz"
LOCAL = ROOT / "tests" / ".golden_local.json"
TINY = TINY_RUN  # the suite's tiny point/2 run (conftest.py)
ARM = [
    "envs=[nlink/2]",
    "data.k_train=30",
    "data.gamma_queries=2000",
    "planner.name=astar",
    "planner.resolution=0.05",
]
#: Max |trained parameter - golden parameter| accepted across machines (see the module doc).
PARAMS_ATOL = 1e-4
#: XLA flags that simulate a foreign CPU in ``test_golden_check_under_foreign_codegen``:
#: a narrower vector unit changes the trained parameters' bits, not the data's.
FOREIGN_XLA_FLAGS = "--xla_cpu_prefer_vector_width=128"
TIME_KEYS = {
    "seconds",
    "compile_seconds",
    "seconds_per_query",
    "reference_seconds_per_query",
    "time",
    "timings",
}
# the CPU features that change what XLA's CPU compiler emits (vector width, FMA, dot units)
_ISA = {
    "sse4_1",
    "sse4_2",
    "avx",
    "avx2",
    "fma",
    "f16c",
    "avx512f",
    "avx512dq",
    "avx512bw",
    "avx512vl",
    "avx512cd",
    "avx512ifma",
    "avx512vbmi",
    "avx512_vnni",
    "avx512_bf16",
    "avx512_fp16",
    "avx_vnni",
    "amx_tile",
    "amx_bf16",
    "amx_int8",
    "asimd",
    "fphp",
    "asimdhp",
    "sve",
    "sve2",
}
_NO_FMA_ISAS = {"SSE4_2", "AVX"}  # --xla_cpu_max_isa values below FMA


# ---------------------------------------------------------------------------
# Numerics fingerprint
# ---------------------------------------------------------------------------


def _cpuinfo() -> dict:
    info: dict = {}
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return {"cpu": platform.processor() or "unknown", "flags": set()}
    for line in text.splitlines():
        if ":" not in line:
            if info:
                break  # the first processor's block is enough
            continue
        k, v = (s.strip() for s in line.split(":", 1))
        info.setdefault(k, v)
    cpu = " ".join(
        info.get(k, "") for k in ("vendor_id", "cpu family", "model", "CPU implementer", "CPU part")
    ).split()
    flags = set((info.get("flags") or info.get("Features") or "").split())
    return {"cpu": " ".join(cpu) or platform.processor() or "unknown", "flags": flags}


def numerics_fingerprint() -> dict:
    """What decides the bits of compiled float code here: versions, CPU, XLA flags.

    Returns ``{"jax", "jaxlib", "arch", "cpu", "isa", "xla_flags"}`` (JSON-ready):
    ``cpu`` is the vendor/family/model (x86) or implementer/part (ARM) of
    ``/proc/cpuinfo`` (``platform.processor()`` elsewhere), ``isa`` the sorted
    vector/FMA features XLA's CPU compiler may use. Two machines with equal
    fingerprints compile the same code; unequal ones may not.
    """
    import jax
    import jaxlib

    ci = _cpuinfo()
    return {
        "jax": jax.__version__,
        "jaxlib": jaxlib.__version__,
        "arch": platform.machine(),
        "cpu": ci["cpu"],
        "isa": sorted(ci["flags"] & _ISA),
        "xla_flags": " ".join(os.environ.get("XLA_FLAGS", "").split()),
    }


def numerics_key(fp: dict) -> str:
    """A short stable key of :func:`numerics_fingerprint`'s dict."""
    return hashlib.sha256(json.dumps(fp, sort_keys=True).encode()).hexdigest()[:16]


def data_class(fp: dict) -> str:
    """``<arch>-fma`` when XLA may fuse multiply-adds on this machine, else ``<arch>-nofma``."""
    isa = set(fp["isa"])
    fma = "fma" in isa or fp["arch"] in ("aarch64", "arm64") or "asimd" in isa
    m = re.search(r"--xla_cpu_max_isa=(\S+)", fp["xla_flags"])
    if m and m.group(1).upper() in _NO_FMA_ISAS:
        fma = False
    return f"{fp['arch']}-{'fma' if fma else 'nofma'}"


# ---------------------------------------------------------------------------
# Fingerprints of a run
# ---------------------------------------------------------------------------


def _h(*arrays) -> str:
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(np.asarray(a))
        h.update(str((a.dtype.str, a.shape)).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:20]


def _datasets(root: Path) -> dict:
    return {str(f.relative_to(root)): _h(np.load(f)) for f in sorted(root.rglob("D*/*.npy"))}


def _numbers(obj):
    """The JSON tree without wall-clock fields and file paths."""
    if isinstance(obj, dict):
        return {
            k: _numbers(v)
            for k, v in sorted(obj.items())
            if k not in TIME_KEYS and not k.endswith("_file")
        }
    if isinstance(obj, list):
        return [_numbers(v) for v in obj]
    return obj


def trained_params(model_dir: Path) -> dict[str, np.ndarray]:
    """The ensemble's parameters in ``model_dir`` as ``{key path: array}``."""
    import jax

    from ntq_jax.training import load_ensemble

    ens = load_ensemble(model_dir)
    return {
        jax.tree_util.keystr(p): np.asarray(v)
        for p, v in jax.tree_util.tree_leaves_with_path(ens.params)
    }


def _paths(run: Path) -> dict:
    out = {}
    for f in sorted((run / "paths").rglob("*.npz")) + sorted((run / "eval").rglob("*.npz")):
        z = np.load(f)
        out[str(f.relative_to(run))] = {
            k: _h(z[k])
            for k in sorted(z.files)
            if k not in TIME_KEYS and k != "fingerprint" and not k.endswith("_seconds")
        }
    return out


def _run_all(tmp: Path, run: Path | None = None) -> tuple[dict, dict[str, np.ndarray]]:
    """Runs the golden pipeline and arm data; ``(fingerprints, trained parameters)``.

    ``run``: a finished run of the golden pipeline (``run_pipeline(cfg, prepare_run(cfg,
    out), progress=False)`` of :data:`TINY`, the test suite's shared one) instead of
    running it here.
    """
    from ntq_jax import data, make_env
    from ntq_jax.experiment import config
    from ntq_jax.experiment.pipeline import load_config, prepare_run, run_pipeline

    if run is None:
        run = tmp / "run"
        cfg = load_config(None, TINY)
        run_pipeline(cfg, prepare_run(cfg, run), progress=False, log=lambda _: None)
    cfg = config.load(None, ARM)
    data.generate_datasets(
        make_env("nlink/2"),
        config.data_options(cfg, "nlink/2"),
        tmp / "arm",
        env_name="nlink/2",
        progress=False,
        figure=False,
    )
    params = trained_params(run / "models" / "point_2")
    rows = _numbers(json.loads((run / "results.json").read_text())["rows"])
    got = {
        "portable": {"pipeline": _datasets(run / "data"), "arm": _datasets(tmp / "arm")},
        "machine": {
            "params": {k: _h(v) for k, v in params.items()},
            "paths": _paths(run),
            "rows_sha": hashlib.sha256(json.dumps(rows, sort_keys=True).encode()).hexdigest()[:20],
        },
    }
    return got, params


# ---------------------------------------------------------------------------
# Comparison
# ---------------------------------------------------------------------------


def params_deviation(params: dict[str, np.ndarray], reference: dict[str, np.ndarray]) -> float:
    """Max |params - reference| over every array (inf if their keys or shapes differ)."""
    if set(params) != set(reference) or any(params[k].shape != reference[k].shape for k in params):
        return float("inf")
    return max(float(np.max(np.abs(params[k].astype(np.float64) - reference[k]))) for k in params)


def _diff(got: dict, want: dict, prefix: str) -> list[str]:
    """The keys of ``want`` whose value ``got`` does not equal (one level, then leaves)."""
    bad = []
    for key, w in want.items():
        g = got.get(key)
        if isinstance(w, dict) and isinstance(g, dict):
            bad += [f"{prefix}/{key}/{k}" for k in sorted(set(w) | set(g)) if g.get(k) != w.get(k)]
        elif g != w:
            bad.append(f"{prefix}/{key}")
    return bad


def compare(
    got: dict,
    params: dict[str, np.ndarray],
    golden: dict,
    reference: dict[str, np.ndarray] | None,
    local: dict | None,
    fp: dict,
) -> tuple[list[str], list[str]]:
    """Holds a run's fingerprints to the records; ``(failures, records to take)``.

    Args:
        got: :func:`_run_all`'s fingerprints (``portable`` and ``machine``).
        params: the trained parameters.
        golden: ``golden.json`` (``portable`` by data class, ``machines`` by key).
        reference: ``golden_params.npz``'s parameters (None: absent).
        local: the local record (``tests/.golden_local.json``) if it belongs to this
            ``golden.json``, else None.
        fp: this machine's :func:`numerics_fingerprint`.

    Returns:
        ``failures`` (one line each; empty: the run matches) and the parts with
        no record for this machine (``"portable"``, ``"machine"``): the caller
        records them locally.
    """
    failures, take = [], []
    cls, key = data_class(fp), numerics_key(fp)
    local = local or {}
    portable = golden.get("portable", {}).get(cls) or local.get("portable", {}).get(cls)
    if portable is None:
        take.append("portable")
    else:
        failures += _diff(got["portable"], portable["datasets"], f"portable[{cls}]")
        if cls == golden.get("params_class") and reference is not None:
            dev = params_deviation(params, reference)
            if not dev <= PARAMS_ATOL:
                failures.append(
                    f"params: max |difference| {dev:.3g} from golden_params.npz "
                    f"exceeds {PARAMS_ATOL:g}"
                )
    records = [
        r
        for r in (golden.get("machines", {}).get(key), local.get("machines", {}).get(key))
        if r is not None
    ]
    if not records:
        take.append("machine")
    for r in records:
        failures += _diff(got["machine"], r["record"], f"machine[{key}]")
    return sorted(set(failures)), take


def _golden_digest() -> str:
    return hashlib.sha256(GOLDEN.read_bytes()).hexdigest()[:16] if GOLDEN.is_file() else ""


def load_local() -> dict | None:
    """The local record, if it was taken beside this ``golden.json``."""
    try:
        rec = json.loads(LOCAL.read_text())
    except (OSError, json.JSONDecodeError):
        return None
    return rec if rec.get("golden_sha") == _golden_digest() else None


def _write_json(path: Path, obj: dict) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(obj, indent=1, sort_keys=True) + "\n")
    os.replace(tmp, path)


def record_local(got: dict, fp: dict, parts) -> None:
    """Adds this machine's ``parts`` of ``got`` to the local record."""
    rec = load_local() or {"golden_sha": _golden_digest(), "portable": {}, "machines": {}}
    if "portable" in parts:
        rec["portable"][data_class(fp)] = {"datasets": got["portable"]}
    if "machine" in parts:
        rec["machines"][numerics_key(fp)] = {"numerics": fp, "record": got["machine"]}
    _write_json(LOCAL, rec)


def _load_reference() -> dict[str, np.ndarray] | None:
    if not GOLDEN_PARAMS.is_file():
        return None
    with np.load(GOLDEN_PARAMS) as z:
        return {k: z[k] for k in z.files}


# ---------------------------------------------------------------------------
# Tests
# ---------------------------------------------------------------------------


def test_outputs_match_golden(tmp_path, tiny_run):
    """The suite's tiny run (conftest.py: the pipeline of TINY, shared with other files) and
    the arm data generated here, against the records."""
    assert tiny_run.config == TINY
    got, params = _run_all(tmp_path, tiny_run.path)
    fp = numerics_fingerprint()
    failures, take = compare(
        got, params, json.loads(GOLDEN.read_text()), _load_reference(), load_local(), fp
    )
    assert not failures, "differs from the golden record:\n" + "\n".join(failures)
    if take:
        record_local(got, fp, take)
        warnings.warn(
            f"golden: no {' or '.join(take)} record for this machine's numerics "
            f"({data_class(fp)}, {numerics_key(fp)}); took one in {LOCAL.name}: "
            "later runs here are compared with it bit for bit"
        )


def _fake_run(scale: float = 1.0):
    got = {
        "portable": {"pipeline": {"a.npy": "1"}, "arm": {"b.npy": "2"}},
        "machine": {"params": {"w": "3"}, "paths": {"p.npz": {"x": "4"}}, "rows_sha": "5"},
    }
    return got, {"w": np.full((2, 3), 0.5 * scale, np.float32)}


def test_compare_holds_each_part_to_its_record():
    """Portable parts strict, parameters within the tolerance, machine parts per fingerprint."""
    fp = {
        "jax": "1",
        "jaxlib": "1",
        "arch": "x86_64",
        "cpu": "c",
        "isa": ["avx2", "fma"],
        "xla_flags": "",
    }
    got, params = _fake_run()
    golden = {
        "portable": {"x86_64-fma": {"datasets": got["portable"]}},
        "params_class": "x86_64-fma",
        "machines": {numerics_key(fp): {"record": got["machine"]}},
    }
    ref = {"w": params["w"] + np.float32(PARAMS_ATOL / 2)}
    assert compare(got, params, golden, ref, None, fp) == ([], [])
    # a dataset byte: fails on every machine of the class, whatever its numerics
    other = dict(fp, cpu="another", isa=["avx2", "avx512f", "fma"])
    bad = json.loads(json.dumps(got))
    bad["portable"]["arm"]["b.npy"] = "changed"
    fails, take = compare(bad, params, golden, ref, None, other)
    assert fails == ["portable[x86_64-fma]/arm/b.npy"] and take == ["machine"]
    # parameters beyond the tolerance fail anywhere; within it they pass on a new machine
    assert compare(got, {"w": params["w"] + np.float32(2 * PARAMS_ATOL)}, golden, ref, None, other)[
        0
    ][0].startswith("params: max |difference|")
    assert compare(got, params, golden, ref, None, other) == ([], ["machine"])
    # a machine part differs from this machine's record (committed or local): fails
    bad = json.loads(json.dumps(got))
    bad["machine"]["paths"]["p.npz"]["x"] = "changed"
    assert compare(bad, params, golden, ref, None, fp)[0] == [
        f"machine[{numerics_key(fp)}]/paths/p.npz"
    ]
    local = {"machines": {numerics_key(other): {"record": got["machine"]}}}
    assert compare(bad, params, golden, ref, local, other)[0] == [
        f"machine[{numerics_key(other)}]/paths/p.npz"
    ]
    # without FMA the data class changes: its portable record is taken, parameters not compared
    nofma = dict(fp, xla_flags="--xla_cpu_max_isa=AVX")
    assert data_class(nofma) == "x86_64-nofma"
    assert compare(got, {"w": params["w"] + 1}, golden, ref, None, nofma)[1] == [
        "portable",
        "machine",
    ]


def test_numerics_fingerprint_sees_xla_flags(monkeypatch):
    monkeypatch.setenv("XLA_FLAGS", "")
    a = numerics_fingerprint()
    monkeypatch.setenv("XLA_FLAGS", FOREIGN_XLA_FLAGS)
    b = numerics_fingerprint()
    assert numerics_key(a) != numerics_key(b) and data_class(a) == data_class(b)
    assert a["jax"] and a["arch"] == platform.machine()


def simulate(tmp: Path) -> dict:
    """The cross-machine parts of the check on this process's numerics, then on a changed byte.

    Generates the golden datasets and trains the PNets (no evaluation: what follows
    training is recorded per machine), holds them to ``golden.json`` (``portable``)
    and ``golden_params.npz``; then changes one byte of D0's ``inputs`` (the exponent
    of one coordinate, its checksum updated so training accepts it), trains again
    and holds that too. Returns both outcomes (JSON-ready).
    """
    from ntq_jax import data, make_env, training
    from ntq_jax.artifacts import npy_sha256
    from ntq_jax.experiment import config
    from ntq_jax.experiment.pipeline import load_config

    cfg = load_config(None, TINY)
    data.generate_datasets(
        make_env("point/2"),
        config.data_options(cfg, "point/2"),
        tmp / "data",
        env_name="point/2",
        progress=False,
        figure=False,
    )
    arm = config.data_options(config.load(None, ARM), "nlink/2")
    data.generate_datasets(
        make_env("nlink/2"), arm, tmp / "arm", env_name="nlink/2", progress=False, figure=False
    )
    golden, reference = json.loads(GOLDEN.read_text()), _load_reference()
    cls = golden["params_class"]

    def check(tag: str) -> dict:
        training.train_from_folder(
            tmp / "data" / "point_2",
            tmp / f"models_{tag}",
            progress=False,
            **config.train_args(cfg),
        )
        params = trained_params(tmp / f"models_{tag}")
        got = {"pipeline": _datasets(tmp / "data"), "arm": _datasets(tmp / "arm")}
        return {
            "datasets_differ": _diff(got, golden["portable"][cls]["datasets"], "portable"),
            "params_deviation": params_deviation(params, reference),
            "params_bit_identical": all(np.array_equal(params[k], reference[k]) for k in reference),
        }

    clean = check("clean")
    f = tmp / "data" / "point_2" / "D0" / "inputs.npy"
    arr = np.load(f)
    arr.view(np.uint8).reshape(-1)[4 * 7 + 3] ^= 0x01  # value 7's exponent: x4 or /4
    np.save(f, arr)
    meta_file = f.with_name("meta.json")
    meta = json.loads(meta_file.read_text())
    meta["arrays"]["inputs"]["sha256"] = npy_sha256(arr)
    meta_file.write_text(json.dumps(meta))
    return {
        "numerics": numerics_fingerprint(),
        "data_class": data_class(numerics_fingerprint()),
        "clean": clean,
        "changed_byte": check("changed"),
    }


def test_golden_check_under_foreign_codegen(tmp_path):
    """A simulated foreign CPU (XLA told other vector widths and fast math) passes the
    cross-machine check with parameters that differ in their bits; a changed dataset
    byte fails it, in the datasets and, after training, in the parameters."""
    env = dict(os.environ, XLA_FLAGS=FOREIGN_XLA_FLAGS, JAX_PLATFORMS="cpu")
    out = tmp_path / "simulated.json"
    proc = subprocess.run(
        [sys.executable, str(Path(__file__)), "--simulate", str(tmp_path), str(out)],
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    r = json.loads(out.read_text())
    assert r["data_class"] == json.loads(GOLDEN.read_text())["params_class"]
    clean, changed = r["clean"], r["changed_byte"]
    assert clean["datasets_differ"] == []
    assert not clean["params_bit_identical"], "the simulation did not change the numerics"
    assert 0 < clean["params_deviation"] <= PARAMS_ATOL
    assert changed["datasets_differ"] == ["portable/pipeline/point_2/D0/inputs.npy"]
    assert changed["params_deviation"] > 10 * PARAMS_ATOL


def record(tmp: Path, *, local_only: bool) -> None:
    """Takes the record of this code on this machine (see the module doc)."""
    got, params = _run_all(tmp)
    fp = numerics_fingerprint()
    if local_only:
        if LOCAL.is_file():
            LOCAL.unlink()
        record_local(got, fp, ("portable", "machine"))
        print(f"recorded {LOCAL} ({data_class(fp)}, {numerics_key(fp)})")
        return
    cls = data_class(fp)
    golden = {
        "format": 2,
        "params_class": cls,
        "portable": {cls: {"datasets": got["portable"]}},
        "machines": {numerics_key(fp): {"numerics": fp, "record": got["machine"]}},
    }
    np.savez(GOLDEN_PARAMS, **params)
    _write_json(GOLDEN, golden)
    LOCAL.unlink(missing_ok=True)
    print(f"recorded {GOLDEN} and {GOLDEN_PARAMS.name} ({cls}, {numerics_key(fp)})")


if __name__ == "__main__":
    import tempfile

    if "--simulate" in sys.argv:
        i = sys.argv.index("--simulate")
        res = simulate(Path(sys.argv[i + 1]))
        Path(sys.argv[i + 2]).write_text(json.dumps(res, indent=1))
    elif "--record" in sys.argv or "--record-local" in sys.argv:
        with tempfile.TemporaryDirectory() as d:
            record(Path(d), local_only="--record-local" in sys.argv)
    else:
        print(__doc__)
