"""Files on disk: atomic writes, fingerprints, compute-or-load, JAX's compilation cache.

Every file the package writes goes through here: the content goes to a hidden
temporary name in the same folder (``.<name>.tmp-<pid>``), is flushed and
fsynced, then renamed over the destination, and the folder is fsynced so the
rename survives a crash. A reader therefore sees the old file or the complete
new one, never a partial one; an interrupted writer leaves only a temporary
file, which :func:`clean_tmp` removes.

A cached result (an ``.npz`` of a planning chunk, a test-query set, a saved
evaluation) carries the :func:`fingerprint` of everything that made it; it is
reused only when the fingerprint matches (:func:`load_npz`,
:func:`compute_or_load`), else computed again.
"""

from __future__ import annotations

import errno
import hashlib
import io
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ntq_jax.errors import UsageError

__all__ = [
    "tmp_name",
    "replace",
    "write_with",
    "write_bytes",
    "write_text",
    "write_json",
    "save_npy",
    "save_npz",
    "save_figure",
    "write_folder",
    "clean_tmp",
    "unwritable_reason",
    "FolderInUse",
    "LockUnsupported",
    "lock_folder",
    "unlock_folder",
    "holds_lock",
    "lock_holder",
    "LOCK_NAME",
    "sha256",
    "json_default",
    "sha256_json",
    "fingerprint",
    "npy_sha256",
    "array_digest",
    "tree_digest",
    "load_npz",
    "compute_or_load",
    "enable_compile_cache",
]


def tmp_name(path: Path) -> Path:
    """The hidden temporary name a write of ``path`` goes through."""
    return path.with_name(f".{path.name}.tmp-{os.getpid()}")


def replace(tmp: Path, dst: Path) -> None:
    """Renames ``tmp`` over ``dst`` and fsyncs the folder, so the rename survives a crash."""
    os.replace(tmp, dst)
    try:
        fd = os.open(dst.parent, os.O_RDONLY)
    except OSError:  # pragma: no cover (platforms without directory fds)
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover
        pass
    finally:
        os.close(fd)


def write_with(path: str | os.PathLike, write: Callable[[Any], None]) -> Path:
    """Atomically writes ``path`` with ``write(binary_file)``; creates the folder."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = tmp_name(path)
    try:
        with open(tmp, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def write_folder(path: str | os.PathLike, fill: Callable[[Path], None]) -> Path:
    """Atomically writes the folder ``path``: ``fill(tmp)`` fills a hidden sibling folder,
    which then replaces ``path`` (an older ``path`` is removed first). ``path`` is
    complete or absent, never half written; an interrupted fill leaves only the hidden
    folder, which the next write of ``path`` removes."""
    import shutil

    path = Path(path).absolute()
    tmp = path.with_name(f".{path.name}.tmp-folder")
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir(parents=True)
    fill(tmp)
    if path.exists():
        shutil.rmtree(path)
    replace(tmp, path)
    return path


def write_bytes(path: str | os.PathLike, blob: bytes) -> Path:
    """Atomic binary write."""
    return write_with(path, lambda f: f.write(blob))


def write_text(path: str | os.PathLike, text: str) -> Path:
    """Atomic text write (UTF-8)."""
    return write_bytes(path, text.encode("utf-8"))


def write_json(path: str | os.PathLike, obj: Any, indent: int | None = 1, **kwargs) -> Path:
    """Atomic JSON write."""
    return write_text(path, json.dumps(obj, indent=indent, **kwargs))


def save_npy(path: str | os.PathLike, arr: np.ndarray) -> Path:
    """Atomic ``.npy`` write (no pickles)."""
    return write_with(path, lambda f: np.save(f, np.ascontiguousarray(arr), allow_pickle=False))


def save_npz(path: str | os.PathLike, **arrays) -> Path:
    """Atomic uncompressed ``.npz`` write."""
    return write_with(path, lambda f: np.savez(f, **arrays))


def save_figure(fig, path: str | os.PathLike, **savefig_kwargs) -> Path:
    """Atomic ``fig.savefig`` (the format comes from ``path``'s suffix)."""
    fmt = Path(path).suffix.lstrip(".") or "png"
    return write_with(path, lambda f: fig.savefig(f, format=fmt, **savefig_kwargs))


def link_tree(src: str | os.PathLike, dst: str | os.PathLike) -> None:
    """``dst`` as a copy of ``src`` made of hard links (a plain copy where links fail); files
    already in ``dst`` are kept."""
    src, dst = Path(src), Path(dst)
    for p in src.rglob("*"):
        q = dst / p.relative_to(src)
        if p.is_dir():
            q.mkdir(parents=True, exist_ok=True)
        elif not q.exists():
            q.parent.mkdir(parents=True, exist_ok=True)
            try:
                os.link(p, q)
            except OSError:
                shutil.copy2(p, q)


def clean_tmp(folder: str | os.PathLike) -> None:
    """Removes the temporary files and folders interrupted writes left in ``folder``."""
    import shutil

    folder = Path(folder)
    if folder.is_dir():
        for p in folder.glob(".*.tmp-*"):
            if p.is_dir() and not p.is_symlink():
                shutil.rmtree(p, ignore_errors=True)
            else:
                p.unlink(missing_ok=True)


def unwritable_reason(folder: str | os.PathLike) -> str | None:
    """Why files cannot be written in ``folder`` (created on write if absent), or None if they can.

    Creates and removes a probe file in ``folder``'s nearest existing ancestor
    (restoring that folder's times), so a read-only file system or folder is
    found even when running as root.
    """
    probe = Path(folder)
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    if not probe.is_dir():
        return f"{probe} is a file, not a folder"
    st = probe.stat()
    try:
        fd, name = tempfile.mkstemp(dir=probe, prefix=".write-test-")
        os.close(fd)
        os.unlink(name)
    except OSError as e:
        return f"creating a file in {probe} failed ({e.strerror})"
    try:  # the probe leaves no trace, not even in the folder's times
        os.utime(probe, ns=(st.st_atime_ns, st.st_mtime_ns))
    except OSError:
        pass
    return None


# ---------------------------------------------------------------------------
# Folder locks: one writer per run folder
# ---------------------------------------------------------------------------

#: The lock file a locked folder holds (its content names the holder).
LOCK_NAME = ".lock"
_HELD: dict[str, list] = {}  # resolved folder -> [lock file descriptor, holder noted]


class FolderInUse(RuntimeError):
    """Another process holds the folder's lock (the message names its pid, host and start)."""


class LockUnsupported(UsageError):
    """The folder's file system has no ``flock`` (ENOLCK, EOPNOTSUPP): one ``error:`` line."""


_NO_LOCKS = {getattr(errno, n) for n in ("ENOLCK", "EOPNOTSUPP", "ENOTSUP") if hasattr(errno, n)}


def lock_folder(folder: str | os.PathLike, note: bool = True) -> Path:
    """Takes the exclusive lock of ``folder`` (which must exist) for this process's lifetime.

    The lock is an advisory ``flock`` on ``<folder>/.lock``, released by the kernel
    when the process ends (a killed run leaves no stale lock). With ``note`` the
    file records the holder's pid, host and start time, which another process's
    :class:`FolderInUse` message names; without it an existing lock file is not
    modified (a caller that may still refuse the folder writes nothing). Taking
    a lock this process already holds returns at once (adding the note if asked).

    Returns:
        The lock file's path.

    Raises:
        FolderInUse: another process holds the lock.
        LockUnsupported: the file system does not support ``flock`` (one line saying so).
    """
    import fcntl

    folder = Path(folder)
    key = str(folder.resolve())
    path = folder / LOCK_NAME
    held = _HELD.get(key)
    if held is not None:
        try:  # still the same file (the folder may have been deleted and made again)
            same = os.fstat(held[0]).st_ino == path.stat().st_ino
        except OSError:
            same = False
        if not same:
            unlock_folder(folder)
            held = None
    if held is None:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as e:
            if e.errno in _NO_LOCKS:
                os.close(fd)
                raise LockUnsupported(
                    f"{folder}: its file system does not support file locks (flock: "
                    f"{(e.strerror or os.strerror(e.errno)).lower()}), which keep two processes "
                    "from writing one folder; use a folder on a local disk"
                ) from None
            who = os.pread(fd, 4096, 0).decode("utf-8", "replace").strip() or "another process"
            os.close(fd)
            raise FolderInUse(f"{folder} is in use by {who}") from None
        held = _HELD[key] = [fd, False]
    if note and not held[1]:
        import socket
        import time

        info = (
            f"pid {os.getpid()} on {socket.gethostname()} since "
            f"{time.strftime('%Y-%m-%d %H:%M:%S')}"
        ).encode()
        os.ftruncate(held[0], 0)
        os.pwrite(held[0], info, 0)
        held[1] = True
    return path


def holds_lock(folder: str | os.PathLike) -> bool:
    """Whether this process holds ``folder``'s lock (:func:`lock_folder`)."""
    return str(Path(folder).resolve()) in _HELD


def lock_holder(folder: str | os.PathLike) -> str | None:
    """Who holds ``folder``'s lock (its note, e.g. ``pid 12 on host since ...``), or None when
    no process does or it cannot be told (no ``/proc/locks``). Never takes the lock."""
    path = Path(folder) / LOCK_NAME
    try:
        st = path.stat()
        table = Path("/proc/locks").read_text()
    except OSError:
        return None
    ident = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
    for line in table.splitlines():  # "1: FLOCK  ADVISORY  WRITE <pid> <dev:ino> 0 EOF"
        parts = line.split()
        if "FLOCK" in parts and "->" not in parts and ident in parts:
            try:
                note = path.read_text(encoding="utf-8", errors="replace").strip()
            except OSError:
                note = ""
            return note or f"pid {parts[parts.index(ident) - 1]}"
    return None


def unlock_folder(folder: str | os.PathLike) -> None:
    """Releases this process's lock of ``folder`` (no-op when it holds none)."""
    held = _HELD.pop(str(Path(folder).resolve()), None)
    if held is not None:
        os.close(held[0])


# ---------------------------------------------------------------------------
# Hashing: every digest the package records is made here
# ---------------------------------------------------------------------------


def sha256(path: str | os.PathLike) -> str:
    """Hex sha256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def json_default(o):
    """``json.dumps`` ``default=`` for NumPy scalars and arrays."""
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.floating):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def sha256_json(obj: Any, default: Callable[[Any], Any] = str) -> str:
    """Hex sha256 of ``obj`` as canonical JSON (``json.dumps`` with sorted keys).

    Equal content gives equal digests whatever the dicts' insertion order;
    ``default`` turns what JSON cannot hold into something it can.
    """
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=default).encode()).hexdigest()


def fingerprint(*parts, default: Callable[[Any], Any] = str) -> str:
    """The first 16 hex digits of :func:`sha256_json` of ``parts``.

    ``default`` turns what JSON cannot hold into something it can (``str`` by
    default; :func:`json_default` for NumPy values). One call, one part: a dict.
    """
    obj = parts[0] if len(parts) == 1 else list(parts)
    return sha256_json(obj, default)[:16]


def npy_sha256(arr: np.ndarray) -> str:
    """Hex sha256 of ``arr``'s ``.npy`` bytes as :func:`save_npy` writes them (C order)."""
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(arr), allow_pickle=False)
    return hashlib.sha256(buf.getbuffer()).hexdigest()


def array_digest(*arrays: np.ndarray) -> str:
    """A 16-hex-digit sha1 of the arrays' bytes (C order), e.g. a dataset's content."""
    h = hashlib.sha1()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def tree_digest(tree: Any) -> str:
    """Hex sha256 over a pytree's leaves: each leaf's key path, dtype, shape and bytes.

    The digest of the values, not of any file holding them: two checkpoints of
    equal weights written at different times have equal digests.
    """
    import jax

    h = hashlib.sha256()
    for path, leaf in jax.tree_util.tree_leaves_with_path(tree):
        a = np.ascontiguousarray(np.asarray(leaf))
        h.update(f"{jax.tree_util.keystr(path)} {a.dtype.str} {a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def load_npz(path: str | os.PathLike, fingerprint: str | None = None) -> dict | None:
    """The arrays of a complete ``.npz``; None if absent, unreadable, or (with
    ``fingerprint``) made from other inputs (its ``fingerprint`` entry differs)."""
    path = Path(path)
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            out = {k: z[k] for k in z.files}
    except Exception:  # noqa: BLE001 - a corrupt or partial file is recomputed
        return None
    if fingerprint is not None and str(out.get("fingerprint", "")) != fingerprint:
        return None
    return out


def compute_or_load(path: str | os.PathLike, fingerprint: str, compute: Callable[[], dict]) -> dict:
    """The arrays saved at ``path`` if their fingerprint matches, else ``compute()``'s,
    saved atomically with the fingerprint (returned dict includes it)."""
    got = load_npz(path, fingerprint)
    if got is None:
        got = dict(compute(), fingerprint=fingerprint)
        save_npz(path, **got)
    return got


def enable_compile_cache(min_compile_seconds: float | None = None) -> None:
    """Turns on JAX's persistent compilation cache.

    The folder is ``$JAX_COMPILATION_CACHE_DIR`` or ``~/.cache/ntq_jax/jax``; only
    compilations over ``min_compile_seconds`` (default
    ``$JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS``, else 2 s) are stored. A
    rerun, a resumed run or ``scripts/plan.py`` then reuse the compiled planners
    and training steps instead of compiling them again. The cache is an optimisation only: if it
    cannot be enabled, nothing changes.
    """
    import jax

    path = os.environ.get(
        "JAX_COMPILATION_CACHE_DIR", str(Path.home() / ".cache" / "ntq_jax" / "jax")
    )
    try:
        jax.config.update("jax_compilation_cache_dir", path)
        jax.config.update(
            "jax_persistent_cache_min_compile_time_secs",
            float(
                min_compile_seconds
                if min_compile_seconds is not None
                else os.environ.get("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", 2.0)
            ),
        )
    except Exception:  # noqa: BLE001 - the cache is an optimisation only
        pass
