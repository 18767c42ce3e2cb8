"""Path records (``scripts/record_paths.py``): what a record is, its checks, its use as data paths.

A record is a folder: ``record.json`` (what was planned: :data:`IDENTITY`, the map,
config, overrides, planner and its options, padding, seed and pool sizes, plus
the fingerprint of the code that last wrote it) and one chunk file per planned
range of each pool, ``U/plan_<a>_<b>.npz`` and ``N/plan_<a>_<b>.npz``
(:data:`CHUNK_KEYS`, as :func:`ntq_jax.planners.jobs.plan_pool` writes them).

Nothing here trusts a record:

* :func:`check_resume`: a recorder resuming a record must have its identity
  (:func:`differences` names what differs), so a record is never overwritten by
  other queries nor mixed from two planners; the planners' worker counts may differ.
* :func:`load_chunk`: a chunk file that cannot be read, lacks an array or has the
  wrong shapes or dtypes is one :class:`RecordError` naming the file and the fix.
* :func:`seed_work`: data generation (``data.per_env[].paths_from``) takes a
  record's chunks only after checking their queries against its own pools and
  verifying every recorded path with the verifier of planned paths
  (:func:`ntq_jax.planners.verify.finalize`, the data padding, the discretised
  check): a path that fails it is unsolved (``rejected``), as a planner's would be.
* :func:`record_digest`: the digest of the chunks a run uses (part of the datasets'
  fingerprint, so a changed record makes the datasets again).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shlex
from pathlib import Path

import numpy as np

from ntq_jax import artifacts
from ntq_jax.types import PlanStatus

__all__ = [
    "RecordError",
    "RECORD_FILE",
    "IDENTITY",
    "CHUNK_KEYS",
    "POOLS",
    "read_record",
    "differences",
    "record_command",
    "check_resume",
    "chunk_files",
    "load_chunk",
    "check_chunks",
    "record_digest",
    "provenance",
    "seed_work",
]

RECORD_FILE = "record.json"
POOLS = ("U", "N")
#: ``record.json`` keys that say what a record holds: a resume must agree on each one
IDENTITY = ("env", "config", "overrides", "planner", "options", "padding", "seed", "pools")
#: planner options and overrides that say how the work runs, not what it plans
RUNTIME_OPTIONS = ("workers",)
_RUNTIME_OVERRIDES = ("planner.workers", "planner.name")  # planner.name: compared as "planner"
CHUNK_FILE = re.compile(r"plan_(\d+)_(\d+)\.npz")
CHUNK_KEYS = ("queries", "paths", "lengths", "costs", "status", "rejected")


class RecordError(ValueError):
    """A record that cannot be used as asked (the message names the file and the fix)."""


def read_record(folder: str | os.PathLike) -> dict:
    """``<folder>/record.json`` as a dict; a :class:`RecordError` if it is missing or unreadable."""
    f = Path(folder) / RECORD_FILE
    if not f.is_file():
        raise RecordError(
            f"{f}: no such file; {folder} is not a record (scripts/record_paths.py "
            "makes one): check the path"
        )
    try:
        meta = json.loads(f.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise RecordError(
            f"{f}: not a readable record ({type(e).__name__}: {e}); restore it "
            "(e.g. from git) or record into a new folder"
        ) from None
    missing = [k for k in IDENTITY if not isinstance(meta, dict) or k not in meta]
    if missing:
        raise RecordError(
            f"{f}: not a record (no {', '.join(missing)}); restore it (e.g. from "
            "git) or record into a new folder"
        )
    return meta


def _overrides(meta: dict) -> dict:
    out = {}
    for ov in meta.get("overrides") or []:
        k, _, v = str(ov).partition("=")
        if k.strip() not in _RUNTIME_OVERRIDES:
            out[k.strip()] = v.strip()
    return out


def _options(meta: dict) -> dict:
    return {k: v for k, v in (meta.get("options") or {}).items() if k not in RUNTIME_OPTIONS}


def differences(saved: dict, now: dict) -> list[str]:
    """What differs between two records' :data:`IDENTITY` (runtime settings aside), one
    ``key: saved (record) != now`` string per difference."""
    out = []
    for key in IDENTITY:
        a, b = saved.get(key), now.get(key)
        if key == "config":
            a, b = os.path.normpath(str(a)), os.path.normpath(str(b))
        elif key == "overrides":
            a, b = _overrides(saved), _overrides(now)
        elif key == "options":
            a, b = _options(saved), _options(now)
        elif key == "padding":
            same = a is not None and b is not None and np.isclose(float(a), float(b))
            a, b = (a, a) if same else (a, b)
        if json.dumps(a, sort_keys=True, default=str) != json.dumps(b, sort_keys=True, default=str):
            out.append(f"{key}: {a!r} (record) != {b!r}")
    return out


def record_command(meta: dict, out: str | os.PathLike) -> str:
    """The ``scripts/record_paths.py`` command of the record ``meta`` (its arguments)."""
    cmd = [
        "python",
        "scripts/record_paths.py",
        "--config",
        str(meta["config"]),
        "--env",
        str(meta["env"]),
        "--planner",
        str(meta["planner"]),
    ]
    for ov in meta.get("overrides") or []:
        k, _, v = str(ov).partition("=")
        if k.strip() == "planner.workers":
            cmd += ["--workers", v.strip()]
        elif k.strip() != "planner.name":
            cmd += ["--set", str(ov)]
    return shlex.join(cmd + ["--out", str(out)])


def check_resume(out: str | os.PathLike, now: dict) -> dict | None:
    """The record already in ``out`` (None: none yet); a :class:`RecordError` when it was
    made with other arguments (naming each difference) or ``out`` is not a record."""
    out = Path(out)
    if not (out / RECORD_FILE).exists():
        if out.is_dir():
            other = sorted(
                p.name for p in out.iterdir() if p.name not in (*POOLS, artifacts.LOCK_NAME)
            )
            if other:
                raise RecordError(
                    f"--out {out}: not a record (it holds {', '.join(other[:3])}"
                    f"{', ...' if len(other) > 3 else ''} and no {RECORD_FILE}); "
                    "give a new or empty folder"
                )
        return None
    saved = read_record(out)
    diff = differences(saved, now)
    if diff:
        raise RecordError(
            f"{out} is a record made with other arguments ({'; '.join(diff)}): a "
            "record is never overwritten or mixed; record into another --out, or "
            f"resume it with its own arguments: {record_command(saved, out)}"
        )
    return saved


def chunk_files(folder: Path, size: int | None = None) -> list[tuple[int, int, Path]]:
    """``(start, stop, file)`` of the chunk files in ``folder`` (a record's pool), sorted;
    with ``size`` only those within the first ``size`` rows."""
    out = []
    for f in Path(folder).glob("plan_*_*.npz"):
        m = CHUNK_FILE.fullmatch(f.name)
        if m and int(m.group(1)) < int(m.group(2)) and (size is None or int(m.group(2)) <= size):
            out.append((int(m.group(1)), int(m.group(2)), f))
    return sorted(out)


def load_chunk(path: Path, d: int, fix: str) -> dict[str, np.ndarray]:
    """The arrays of the chunk file ``path`` of ``d``-dimensional states, checked: every key
    of :data:`CHUNK_KEYS`, one row per query of its range, integer statuses and lengths
    within the paths; otherwise one :class:`RecordError` naming the file and ``fix``."""

    def bad(why: str) -> RecordError:
        return RecordError(f"{path}: {why}; {fix}")

    lo, hi = map(int, CHUNK_FILE.fullmatch(path.name).groups())
    k = hi - lo
    try:
        with np.load(path, allow_pickle=False) as z:
            got = {key: z[key] for key in z.files if key in CHUNK_KEYS}
    except Exception as e:  # noqa: BLE001 - truncated, empty, not a zip, bad member
        raise bad(f"not a readable chunk file ({type(e).__name__}: {e})") from None
    missing = [key for key in CHUNK_KEYS if key not in got]
    if missing:
        raise bad(f"not a chunk file (no {', '.join(missing)})")
    p = got["paths"]
    for key, want, text in (
        ("queries", (k, 2, d), f"({k}, 2, {d})"),
        ("paths", (k, p.shape[1] if p.ndim == 3 else -1, d), f"({k}, L, {d})"),
    ):
        if got[key].shape != want or got[key].dtype.kind != "f":
            raise bad(
                f"{key} of shape {got[key].shape} ({got[key].dtype}), expected {text} "
                f"floats ({k} queries of {d}-dimensional states)"
            )
    for key, kinds in (("lengths", "iu"), ("costs", "fiu"), ("status", "iu"), ("rejected", "biu")):
        if got[key].shape != (k,) or got[key].dtype.kind not in kinds:
            raise bad(f"{key} of shape {got[key].shape} ({got[key].dtype}), expected ({k},)")
    n = got["lengths"]
    if ((n < 0) | (n > p.shape[1])).any():
        raise bad(f"path lengths outside 0..{p.shape[1]}")
    if not np.isin(got["status"], [int(s) for s in PlanStatus]).all():
        raise bad("statuses that are not a PlanStatus")
    return got


def check_chunks(folder: Path, pools: dict[str, np.ndarray], fix: str) -> int:
    """Checks every chunk file of the record ``folder`` against ``pools`` (name -> the
    pool's queries ``(n, 2, d)``): readable and of the pool's queries, else one
    :class:`RecordError` naming the file. Returns the number of queries covered."""
    covered = 0
    for name, queries in pools.items():
        for lo, hi, f in chunk_files(folder / name, len(queries)):
            z = load_chunk(f, queries.shape[2], fix)
            if not np.array_equal(z["queries"], queries[lo:hi]):
                raise RecordError(
                    f"{f}: its queries are not the pool rows {lo}..{hi} of these "
                    "arguments (another sampler or code version made them); "
                    "record into another --out (this record stays as it is)"
                )
            covered += hi - lo
    return covered


def record_digest(folder: str | os.PathLike, sizes: dict[str, int]) -> str:
    """sha256 of the record's identity and the bytes of the chunk files within ``sizes``
    (pool -> rows a run uses): it changes when any chunk a run reads changes."""
    folder = Path(folder)
    meta = read_record(folder)
    h = hashlib.sha256(
        json.dumps({k: meta[k] for k in IDENTITY}, sort_keys=True, default=str).encode()
    )
    for name in POOLS:
        for lo, hi, f in chunk_files(folder / name, sizes.get(name, 0)):
            h.update(f"{name}/{f.name}:{artifacts.sha256(f)}\n".encode())
    return h.hexdigest()[:16]


def provenance(folder: str | os.PathLike, sizes: dict[str, int]) -> dict:
    """What a dataset's ``meta.json`` records of the record its paths come from."""
    meta = read_record(folder)
    return {
        "record": str(folder),
        "env": meta["env"],
        "planner": meta["planner"],
        "options": meta["options"],
        "seed": meta["seed"],
        "digest": record_digest(folder, sizes),
    }


def seed_work(
    work: Path,
    record: str | os.PathLike,
    pool: np.ndarray,
    n_u: int,
    env,
    *,
    env_name: str,
    seed: int,
    padding: float,
) -> tuple[int, int]:
    """Copies a record's chunks, checked and verified, into ``work`` as pooled chunk files.

    The record's ``U/plan_<a>_<b>.npz`` become ``plan_<a>_<b>.npz`` and its
    ``N/plan_<a>_<b>.npz`` become ``plan_<n_u+a>_<n_u+b>.npz``, so that
    :func:`ntq_jax.planners.jobs.plan_pool` reuses them; chunks beyond the pools are
    ignored (a larger record serves a smaller run). Each chunk's paths are verified
    (:func:`ntq_jax.planners.verify.finalize` at ``padding``): a recorded SOLVED path
    that fails becomes NO_PATH and ``rejected``.

    Returns:
        ``(queries seeded, recorded paths rejected by the verification)``.

    Raises:
        RecordError: the record is of another map, padding or seed, a chunk's queries
            are not this run's, or a file is unreadable or malformed (naming it).
    """
    from ntq_jax.planners.verify import finalize

    record = Path(record)
    meta = read_record(record)
    if (
        meta["env"] != env_name
        or not np.isclose(float(meta["padding"]), padding)
        or meta["seed"] != seed
    ):
        raise RecordError(
            f"{record} records {meta['env']} at padding {meta['padding']} with seed "
            f"{meta['seed']}, not {env_name} at {padding} with seed {seed}: point "
            "data.per_env's paths_from at this map's record"
        )
    fix = (
        f"re-plan it (delete the file, then run {record_command(meta, record)}) or point "
        "paths_from at an intact record"
    )
    spans = {"U": (0, n_u), "N": (n_u, len(pool))}
    seeded = rejected = 0
    for name, (lo0, hi0) in spans.items():
        for a, b, f in chunk_files(record / name, hi0 - lo0):
            z = load_chunk(f, pool.shape[2], fix)
            if not np.array_equal(z["queries"], pool[lo0 + a : lo0 + b]):
                raise RecordError(
                    f"{f}: its queries are not this run's pool rows {lo0 + a}.."
                    f"{lo0 + b} (the record was made with another config, seed or "
                    "sampler); point paths_from at a record of this config"
                )
            seeded += b - a
            dest = work / f"plan_{lo0 + a:09d}_{lo0 + b:09d}.npz"
            if dest.exists():
                continue
            status = z["status"].astype(np.int8)
            res = finalize(
                z["queries"],
                z["paths"].astype(np.float32),
                z["lengths"].astype(np.int32),
                status,
                {},
                env,
                padding,
            )
            rej = z["rejected"].astype(bool) | ((status == PlanStatus.SOLVED) & ~res.solved)
            rejected += int(((status == PlanStatus.SOLVED) & ~res.solved).sum())
            artifacts.save_npz(
                dest,
                queries=z["queries"],
                paths=res.paths,
                lengths=res.lengths,
                costs=res.costs,
                status=res.status,
                rejected=rej,
            )
    return seeded, rejected
