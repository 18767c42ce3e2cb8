"""Bit-identical outputs against golden hashes recorded before the architecture refactor.

A tiny pipeline run (point/2: grid A* data, four PNets, neural planning, report)
and a data-only run of the 2-link arm (grid A* in joint space) are fingerprinted:
the bytes of every dataset array, the trained parameters, every saved planned
path and every number of ``results.json`` except wall-clock times. The golden
values in ``tests/golden.json`` were taken from the code before the refactor
(commit 04d95da) on this machine's JAX (recorded in the file): a refactor that
changes any output by one bit fails here.

Re-record (only for a deliberate change of results)::

    python tests/test_golden.py --record
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
GOLDEN = ROOT / "tests" / "golden.json"
TINY = ["envs=[point/2]", "data.k_train=40", "data.gamma_queries=2000", "data.gamma_eval=false",
        "train.epochs=2", "model.hidden=[32,32]", "eval.k_test=16", "eval.n_plan=20",
        "eval.replan_rounds=2", "eval.replan_steps=6", "eval.gamma_queries=2000"]
ARM = ["envs=[nlink/2]", "data.k_train=30", "data.gamma_queries=2000", "planner.name=astar",
       "planner.resolution=0.05"]
# result fields added after the recording (not part of the golden record)
NEW_KEYS = {"data_planner", "band_padding", "n_in_band", "n_out_band", "successes_in_band",
            "successes_out_band", "success_in_band", "success_out_band", "success_in_band_ci95",
            "success_out_band_ci95",
            # results.json's top-level "comparisons" (paired tests, ntq_jax.report.comparisons):
            # only "rows" is fingerprinted, so this section is outside the record anyway
            "comparisons"}


def _new_model(name: str) -> bool:
    """Models added after the recording: the ensemble rows (``eval.ensemble``, on by default).

    True for a result row's model ``PNet_ens`` / ``PNet_best-of-<N>`` / ``PNet_cascade`` and
    for their paths files ``paths/<env>/PNet_ens_*.npz`` / ``PNet_best-of-<N>_*.npz`` /
    ``PNet_cascade_*.npz`` / ``validation*.npz`` (the cascade's member order): these rows
    and files are not part of the golden record and are skipped; every PNet_0..3 row and
    file is still compared bit for bit.
    """
    return name in ("PNet_ens", "PNet_cascade") or name.startswith(
        ("PNet_ens_", "PNet_best-of-", "PNet_cascade_", "validation"))


TIME_KEYS = {"seconds", "compile_seconds", "seconds_per_query", "reference_seconds_per_query",
             "time", "timings"}


def _h(*arrays) -> str:
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(np.asarray(a))
        h.update(str((a.dtype.str, a.shape)).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:20]


def _datasets(root: Path) -> dict:
    out = {}
    for f in sorted(root.rglob("D*/*.npy")):
        out[str(f.relative_to(root))] = _h(np.load(f))
    return out


def _numbers(obj):
    """The JSON tree without wall-clock fields and file paths."""
    if isinstance(obj, dict):
        return {k: _numbers(v) for k, v in sorted(obj.items())
                if k not in TIME_KEYS | NEW_KEYS and not k.endswith("_file")}
    if isinstance(obj, list):
        return [_numbers(v) for v in obj]
    return obj


def fingerprint_pipeline(run: Path) -> dict:
    from ntq_jax.training import load_ensemble

    ens = load_ensemble(run / "models" / "point_2")
    import jax
    leaves = jax.tree_util.tree_leaves_with_path(ens.params)
    params = {jax.tree_util.keystr(p): _h(v) for p, v in leaves}
    paths = {}
    for f in sorted((run / "paths").rglob("*.npz")) + sorted((run / "eval").rglob("*.npz")):
        if _new_model(f.name):
            continue
        z = np.load(f)
        paths[str(f.relative_to(run))] = {k: _h(z[k]) for k in sorted(z.files)
                                          if k not in TIME_KEYS and k != "fingerprint"
                                          and not k.endswith("_seconds")}
    res = json.loads((run / "results.json").read_text())
    rows = _numbers([r for r in res["rows"] if not _new_model(r["model"])])
    return {"datasets": _datasets(run / "data"), "params": params, "paths": paths,
            "rows_sha": hashlib.sha256(json.dumps(rows, sort_keys=True).encode()).hexdigest()[:20]}


def fingerprint_arm(out: Path) -> dict:
    return {"datasets": _datasets(out)}


def _run_all(tmp: Path) -> dict:
    from ntq_jax import config, data, make_env
    from ntq_jax.pipeline import load_config, prepare_run, run_pipeline

    cfg = load_config(None, TINY)
    run_pipeline(cfg, prepare_run(cfg, tmp / "run"), progress=False)
    cfg = config.load(None, ARM)
    data.generate_datasets(make_env("nlink/2"), cfg, tmp / "arm", env_name="nlink/2",
                           progress=False, figure=False)
    return {"pipeline": fingerprint_pipeline(tmp / "run"), "arm": fingerprint_arm(tmp / "arm")}


def test_outputs_bit_identical_to_golden(tmp_path):
    golden = json.loads(GOLDEN.read_text())
    got = _run_all(tmp_path)
    for part in ("pipeline", "arm"):
        for key, want in golden[part].items():
            assert got[part][key] == want, f"{part}/{key} differs from the golden record"


if __name__ == "__main__" and "--record" in sys.argv:
    import tempfile

    import jax
    with tempfile.TemporaryDirectory() as d:
        rec = _run_all(Path(d))
    rec["jax"] = jax.__version__
    GOLDEN.write_text(json.dumps(rec, indent=1, sort_keys=True) + "\n")
    print(f"recorded {GOLDEN}")
