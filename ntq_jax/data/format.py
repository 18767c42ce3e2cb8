"""The on-disk dataset format: writing, validating loading, the environment figure.

An environment folder ``<out>/<env_slug>/`` holds ``env.json``, ``figure.png``
and one folder per dataset ``D0``, ``D1``, ... with uncompressed ``.npy``
arrays (:data:`ARRAY_SPECS`) and ``meta.json``:

* ``inputs`` float32 ``(N, 2d)`` (current, goal), ``targets`` float32 ``(N, d)``
  (next waypoint), ``path_index`` int32 ``(N,)`` (row of ``paths``);
* ``paths`` float32 ``(P, L_max, d)`` NaN-padded (the solved queries' paths in
  query order), ``path_lengths`` int32 ``(P,)``;
* ``queries`` float32 ``(K, 2, d)``, ``query_kind`` int8 ``(K,)`` (0 uniform,
  1 non-trivial, 2 :data:`ntq_jax.queries.NT_EXHAUSTED`), ``solved`` bool ``(K,)``.

``meta.json`` holds the settings, the statistics and the dtype, shape and sha256
of every array. It is written last (and removed first on a rewrite), so a folder
without it is incomplete. A dataset is complete only when verified
(:func:`dataset_problem`): every array's ``.npy`` header and file size match
its entry and its sha256 matches (one read of each file). :func:`load_dataset` refuses incomplete,
corrupt or inconsistent folders with a :class:`DatasetError` naming the file and
the command that regenerates it (:func:`regenerate_hint`: the environment
folder's ``config.yaml``, written by the generator, makes it exact).
"""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ntq_jax import artifacts, plotting
from ntq_jax.envs import Env

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "ARRAY_SPECS",
    "Dataset",
    "DatasetError",
    "dataset_names",
    "meta_bytes",
    "recorded_checksums",
    "regenerate_hint",
    "dataset_problem",
    "damaged_datasets",
    "is_complete",
    "write_dataset",
    "load_dataset",
    "load_datasets",
    "plot_environment",
]

#: The ``format`` field of a dataset's ``meta.json``.
FORMAT = "ntq_jax.dataset"
#: The version of the dataset layout (``meta.json`` ``format_version``).
FORMAT_VERSION = 1

#: The arrays of a dataset file: name -> (dtype, ndim).
ARRAY_SPECS: dict[str, tuple[np.dtype, int]] = {
    "inputs": (np.dtype(np.float32), 2),
    "targets": (np.dtype(np.float32), 2),
    "path_index": (np.dtype(np.int32), 1),
    "paths": (np.dtype(np.float32), 3),
    "path_lengths": (np.dtype(np.int32), 1),
    "queries": (np.dtype(np.float32), 3),
    "query_kind": (np.dtype(np.int8), 1),
    "solved": (np.dtype(np.bool_), 1),
}

#: The generator's copy of the resolved config in every environment folder.
CONFIG_FILE = "config.yaml"


class DatasetError(ValueError):
    """A missing, truncated, corrupt or inconsistent dataset; the message names the file and the fix."""


class Dataset(NamedTuple):
    """One dataset folder (see the module docstring for shapes and dtypes).

    Attributes:
        inputs: ``(N, 2d)`` float32 (current state, goal state).
        targets: ``(N, d)`` float32 next waypoint.
        path_index: ``(N,)`` int32 row of ``paths`` each sample comes from.
        paths: ``(P, L_max, d)`` float32 solved paths, NaN after ``path_lengths``.
        path_lengths: ``(P,)`` int32 waypoints per path.
        queries: ``(K, 2, d)`` float32 start and goal of every query.
        query_kind: ``(K,)`` int8 0 uniform, 1 non-trivial, 2 non-trivial sampler exhausted.
        solved: ``(K,)`` bool the planner solved the query (the ``P`` paths, in order).
        meta: the parsed ``meta.json``.
    """

    inputs: np.ndarray
    targets: np.ndarray
    path_index: np.ndarray
    paths: np.ndarray
    path_lengths: np.ndarray
    queries: np.ndarray
    query_kind: np.ndarray
    solved: np.ndarray
    meta: dict


def dataset_names(n: int) -> list[str]:
    """``['D0', ..., 'D{n-1}']``."""
    return [f"D{i}" for i in range(n)]


# ---------------------------------------------------------------------------
# Writing
# ---------------------------------------------------------------------------


def meta_bytes(obj) -> bytes:
    """``meta.json``'s bytes: sorted keys, indent 1, NumPy values as JSON numbers."""
    return (
        json.dumps(obj, indent=1, sort_keys=True, default=artifacts.json_default) + "\n"
    ).encode()


def _env_name_of(env_dir: Path) -> str | None:
    """The environment name recorded in any readable ``D<i>/meta.json`` of ``env_dir``."""
    for mpath in sorted(env_dir.glob("D*/meta.json")):
        try:
            name = json.loads(mpath.read_text()).get("env_name")
        except (OSError, UnicodeDecodeError, json.JSONDecodeError, AttributeError):
            continue
        if isinstance(name, str) and name:
            return name
    return None


def regenerate_hint(env_dir, env_name: str | None = None) -> str:
    """The advice that ends every dataset error: the command that regenerates ``env_dir``.

    With the generator's ``<env_dir>/config.yaml`` (or, for a pipeline run
    folder ``<run>/data/<env>``, ``<run>/config.yaml``) and the environment's
    name (``env_name``, else from any readable ``meta.json``), it is the exact
    ``scripts/generate_data.py --config ... --out ... --env ...`` command,
    which verifies every dataset and rewrites only the damaged ones. Otherwise
    it asks for the command that wrote the folder to be rerun.
    """
    env_dir = Path(env_dir)
    config = env_dir / CONFIG_FILE
    run_config = env_dir.parent.parent / CONFIG_FILE
    if not config.is_file() and env_dir.parent.name == "data" and run_config.is_file():
        config = run_config
    env_name = env_name or _env_name_of(env_dir)
    if config.is_file() and env_name:
        cmd = " ".join(
            [
                "python scripts/generate_data.py",
                "--config",
                shlex.quote(str(config)),
                "--out",
                shlex.quote(str(env_dir.parent)),
                "--env",
                shlex.quote(env_name),
            ]
        )
        return f"regenerate it with: {cmd} (it rewrites only the damaged datasets)"
    return (
        f"regenerate it by rerunning the scripts/generate_data.py command that wrote "
        f"{env_dir} (same --config, --set and --out; it rewrites only the damaged datasets)"
    )


def _npy_layout(f: Path) -> tuple[np.dtype, tuple[int, ...], int]:
    """``(dtype, shape, expected file size)`` from a ``.npy`` header (reads only the header)."""
    with open(f, "rb") as fh:
        version = np.lib.format.read_magic(fh)
        if version == (1, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_1_0(fh)
        elif version == (2, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_2_0(fh)
        else:
            raise ValueError(f"unsupported .npy version {version}")
        offset = fh.tell()
    return dtype, tuple(shape), offset + int(np.prod(shape, dtype=np.int64)) * dtype.itemsize


def _array_problem(f: Path, want, checksum: bool) -> str | None:
    """Why ``f`` does not match its ``meta.json`` entry ``want``, or None."""
    if not isinstance(want, dict):
        return f"{f.parent / 'meta.json'} has no entry for {f.name}"
    if not f.is_file():
        return f"{f}: missing"
    try:
        dtype, shape, size = _npy_layout(f)
    except (OSError, ValueError, EOFError) as e:
        return f"{f}: unreadable .npy header ({e})"
    if dtype.str != want.get("dtype") or list(shape) != list(want.get("shape", [])):
        return (
            f"{f}: dtype {dtype} shape {tuple(shape)} differs from meta.json (dtype "
            f"{want.get('dtype')}, shape {want.get('shape')})"
        )
    actual = f.stat().st_size
    if actual != size:
        return f"{f}: truncated or corrupt ({actual} bytes, its header needs {size})"
    if checksum and artifacts.sha256(f) != want.get("sha256"):
        return f"{f}: corrupt (sha256 differs from meta.json)"
    return None


def dataset_problem(folder, fingerprint: str | None = None, checksum: bool = True) -> str | None:
    """Why the dataset ``folder`` is not complete and intact, or None when it is.

    Checks that ``meta.json`` parses (and has ``fingerprint``, when given) and
    that every array's ``.npy`` header (dtype, shape) and file size match it;
    with ``checksum`` also every array's sha256 (one read of each file).
    """
    folder = Path(folder)
    mpath = folder / "meta.json"
    try:
        meta = json.loads(mpath.read_text())
    except FileNotFoundError:
        return f"{mpath}: missing (generation not finished)"
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        return f"{mpath}: unreadable ({e})"
    if not isinstance(meta, dict) or not isinstance(meta.get("arrays"), dict):
        return f"{mpath}: not an ntq_jax dataset's metadata"
    if fingerprint is not None and meta.get("fingerprint") != fingerprint:
        return f"{mpath}: written with other settings (fingerprint differs)"
    for name in ARRAY_SPECS:
        why = _array_problem(folder / f"{name}.npy", meta["arrays"].get(name), checksum)
        if why:
            return why
    return None


def damaged_datasets(
    env_dir, names: list[str], fingerprint: str | None = None, checksum: bool = True
) -> dict[str, str]:
    """``{name: problem}`` for every dataset of ``names`` that :func:`dataset_problem` rejects."""
    env_dir = Path(env_dir)
    out = {}
    for nm in names:
        why = dataset_problem(env_dir / nm, fingerprint, checksum)
        if why:
            out[nm] = why
    return out


def is_complete(env_dir: Path, names: list[str], fingerprint: str, checksum: bool = True) -> bool:
    """Every dataset of ``names`` is written with this ``fingerprint`` and verified intact."""
    return not damaged_datasets(env_dir, names, fingerprint, checksum)


def recorded_checksums(env_dir, names: list[str]) -> dict[str, dict[str, str] | None]:
    """Per dataset name, ``{array: sha256}`` as its ``meta.json`` records them; None for a
    dataset whose ``meta.json`` is absent or unreadable. Reads no array."""
    out: dict[str, dict[str, str] | None] = {}
    for nm in names:
        try:
            arrays = json.loads((Path(env_dir) / nm / "meta.json").read_text())["arrays"]
            out[nm] = {a: v["sha256"] for a, v in arrays.items()}
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            out[nm] = None
    return out


def write_dataset(folder: Path, arrays: dict[str, np.ndarray], meta: dict) -> None:
    """Writes one dataset folder: ``meta.json`` removed first, arrays atomically, ``meta.json`` last."""
    folder.mkdir(parents=True, exist_ok=True)
    artifacts.clean_tmp(folder)
    (folder / "meta.json").unlink(missing_ok=True)
    info = {}
    for name, (dtype, ndim) in ARRAY_SPECS.items():
        arr = np.asarray(arrays[name])
        assert arr.dtype == dtype and arr.ndim == ndim, (name, arr.dtype, arr.shape)
        digest = artifacts.sha256(artifacts.save_npy(folder / f"{name}.npy", arr))
        info[name] = {"dtype": dtype.str, "shape": list(arr.shape), "sha256": digest}
    artifacts.write_bytes(folder / "meta.json", meta_bytes(dict(meta, arrays=info)))


# ---------------------------------------------------------------------------
# Loading
# ---------------------------------------------------------------------------


def _read_meta(folder: Path, fix: str) -> dict:
    mpath = folder / "meta.json"
    if not folder.is_dir():
        raise DatasetError(f"{folder}: no such dataset folder; {fix}")
    if not mpath.is_file():
        raise DatasetError(
            f"{mpath}: missing, the dataset is incomplete (generation interrupted?); {fix}"
        )
    try:
        meta = json.loads(mpath.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise DatasetError(f"{mpath}: not valid JSON ({e}); {fix}") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        found = meta.get("format") if isinstance(meta, dict) else type(meta).__name__
        raise DatasetError(
            f"{mpath}: not an ntq_jax dataset (format {found!r}, expected {FORMAT!r}); {fix}"
        )
    if meta.get("format_version") != FORMAT_VERSION:
        raise DatasetError(
            f"{mpath}: format version {meta.get('format_version')!r}, this "
            f"ntq_jax reads {FORMAT_VERSION}; {fix}"
        )
    return meta


def _read_array(folder: Path, name: str, want, mmap: bool, verify: bool, fix: str) -> np.ndarray:
    dtype, ndim = ARRAY_SPECS[name]
    f = folder / f"{name}.npy"
    if not f.is_file():
        raise DatasetError(f"{f}: missing; {fix}")
    if not isinstance(want, dict):
        raise DatasetError(f"{folder / 'meta.json'}: no entry for array {name!r}; {fix}")
    why = _array_problem(f, want, verify)
    if why:
        raise DatasetError(f"{why}; {fix}")
    try:
        if mmap and f.stat().st_size > 0:
            try:
                a = np.load(f, mmap_mode="r", allow_pickle=False)
            except ValueError:
                a = np.load(f, allow_pickle=False)  # e.g. zero-size arrays cannot be mapped
        else:
            a = np.load(f, allow_pickle=False)
    except (OSError, ValueError, EOFError) as e:
        raise DatasetError(f"{f}: truncated or corrupt ({e}); {fix}") from None
    if a.dtype != dtype or a.ndim != ndim:
        raise DatasetError(
            f"{f}: dtype {a.dtype} shape {a.shape}, expected {dtype} with {ndim} dimensions; {fix}"
        )
    if list(a.shape) != list(want.get("shape", [])):
        raise DatasetError(
            f"{f}: shape {a.shape} differs from meta.json {want.get('shape')}; {fix}"
        )
    return a


def load_dataset(folder, mmap: bool = True, verify: bool = True) -> Dataset:
    """Loads and validates one dataset folder.

    Args:
        folder: a ``D<i>`` folder.
        mmap: memory-map the arrays (``mmap_mode="r"``).
        verify: check each file's sha256 against ``meta.json`` (detects corruption).

    Raises:
        DatasetError: missing/unparsable ``meta.json`` (an incomplete dataset),
            a missing, truncated or corrupt array, or shapes/dtypes inconsistent
            with each other or with the metadata; the message names the file and the fix.
    """
    folder = Path(folder)
    fix = regenerate_hint(folder.parent)
    meta = _read_meta(folder, fix)
    info = meta.get("arrays") or {}
    arrs = {
        name: _read_array(folder, name, info.get(name), mmap, verify, fix) for name in ARRAY_SPECS
    }
    _check_consistency(folder, arrs, meta, fix)
    return Dataset(meta=meta, **arrs)


def _check_consistency(folder: Path, a: dict, meta: dict, fix: str):
    def bad(msg):
        raise DatasetError(f"{folder}: {msg}; {fix}")

    K, two, d = a["queries"].shape
    if two != 2:
        bad(f"queries.npy has shape {a['queries'].shape}, expected (K, 2, d)")
    N = a["inputs"].shape[0]
    P = a["paths"].shape[0]
    if a["inputs"].shape[1] != 2 * d:
        bad(f"inputs.npy has {a['inputs'].shape[1]} columns, expected 2d = {2 * d}")
    if a["targets"].shape != (N, d):
        bad(f"targets.npy shape {a['targets'].shape}, expected ({N}, {d})")
    if a["path_index"].shape != (N,):
        bad(f"path_index.npy shape {a['path_index'].shape}, expected ({N},)")
    if a["query_kind"].shape != (K,) or a["solved"].shape != (K,):
        bad(f"query_kind/solved must have shape ({K},)")
    if a["path_lengths"].shape != (P,):
        bad(f"path_lengths.npy shape {a['path_lengths'].shape}, expected ({P},)")
    if P and a["paths"].shape[2] != d:
        bad(f"paths.npy shape {a['paths'].shape}, expected (P, L, {d})")
    if int(np.count_nonzero(a["solved"])) != P:
        bad(f"{int(np.count_nonzero(a['solved']))} solved queries but {P} paths")
    if N and (int(a["path_index"].min()) < 0 or int(a["path_index"].max()) >= P):
        bad("path_index.npy points outside paths.npy")
    if P and (
        int(a["path_lengths"].min()) < 2 or int(a["path_lengths"].max()) > a["paths"].shape[1]
    ):
        bad("path_lengths.npy out of range [2, L_max]")
    kinds = np.unique(np.asarray(a["query_kind"]))
    if np.any((kinds < 0) | (kinds > 2)):
        bad(f"query_kind.npy holds values {kinds.tolist()}, expected 0, 1 or 2")
    st = meta.get("stats", {})
    if st.get("samples") is not None and st["samples"] != N:
        bad(f"meta.json says {st['samples']} samples, inputs.npy holds {N}")
    if st.get("queries") is not None and st["queries"] != K:
        bad(f"meta.json says {st['queries']} queries, queries.npy holds {K}")


def load_datasets(env_dir, mmap: bool = True, verify: bool = True) -> list[Dataset]:
    """Loads ``D0, D1, ...`` of one environment folder (all ``D<i>`` present, in order).

    Raises:
        DatasetError: no dataset folder, a gap in the numbering, or any dataset invalid.
    """
    env_dir = Path(env_dir)
    found = sorted(
        (int(p.name[1:]), p)
        for p in env_dir.glob("D*")
        if p.is_dir() and re.fullmatch(r"D\d+", p.name)
    )
    if not found:
        raise DatasetError(
            f"{env_dir}: no D0..D3 dataset folders; generate them with scripts/generate_data.py"
        )
    if [i for i, _ in found] != list(range(len(found))):
        raise DatasetError(
            f"{env_dir}: dataset folders {[p.name for _, p in found]} are not "
            f"D0..D{len(found) - 1}; {regenerate_hint(env_dir)}"
        )
    return [load_dataset(p, mmap=mmap, verify=verify) for _, p in found]


def plot_environment(env_dir, out=None, n_points: int = 400, n_paths: int = 6) -> Path:
    """:func:`ntq_jax.plotting.dataset_figure` of a dataset folder (default ``<env_dir>/figure.png``)."""
    env_dir = Path(env_dir)
    env = Env.from_json(json.loads((env_dir / "env.json").read_text()))
    out = Path(out) if out is not None else env_dir / "figure.png"
    return plotting.dataset_figure(
        env, load_datasets(env_dir, verify=False), out, n_points=n_points, n_paths=n_paths
    )
