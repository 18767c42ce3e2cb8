"""Command-line error handling shared by the scripts: expected errors become one line.

Every script's entry point goes through :func:`run_cli`::

    def main(argv=None) -> int:
        return run_cli(lambda: _main(argv))

The package's expected exceptions (:class:`UsageError` for a bad argument,
:data:`EXPECTED_ERRORS`: a bad environment, config, dataset, checkpoint or run
folder, a path that is missing, not writable or of the wrong kind) are printed as one ``error:
<message>`` line on stderr
(their messages name the problem and the fix) and give exit code 2; Ctrl-C
gives one ``interrupted`` line and exit code 130. Anything else is a bug and
keeps its traceback.
"""

from __future__ import annotations

import errno
import logging
import os
import sys
from pathlib import Path
from typing import Callable, Iterable

from ntq_jax.errors import UsageError  # re-exported: the scripts import it from here

__all__ = [
    "UsageError",
    "EXPECTED_ERRORS",
    "PATH_ERRORS",
    "expected_error_types",
    "error_line",
    "positive_int",
    "seed_arg",
    "check_writable",
    "check_writable_folder",
    "add_run_options",
    "add_executor_options",
    "executor_of",
    "start_run",
    "run_cli",
]


#: ``(module, class name)`` of the package's expected exceptions. They are looked
#: up in :data:`sys.modules` only: an exception can only be raised by a module
#: that was imported, so the lookup never imports anything (``--help`` stays fast).
EXPECTED_ERRORS: tuple[tuple[str, str], ...] = (
    ("ntq_jax.envs", "EnvError"),
    ("ntq_jax.errors", "ConfigError"),
    ("ntq_jax.data.format", "DatasetError"),
    ("ntq_jax.data.records", "RecordError"),
    ("ntq_jax.training.checkpoint", "CheckpointError"),
    ("ntq_jax.experiment.pipeline", "PipelineError"),
    ("ntq_jax.queries", "FreeSpaceTooSmall"),
    ("ntq_jax.experiment.summaries", "SummaryError"),
)

#: Path errors and the fix each one calls for.
PATH_ERRORS: dict[type[OSError], str] = {
    PermissionError: "choose a writable location or change its permissions",
    FileNotFoundError: "check the path",
    IsADirectoryError: "a file was expected there, not a folder",
    NotADirectoryError: "a folder was expected there, but the path (or one of its parents) "
    "is a file",
    FileExistsError: "a folder is needed there but a file of that name exists; choose another "
    "path or remove the file",
}


#: ``errno`` of a full or read-only disk: expected wherever they arise (also wrapped by a
#: library, e.g. Orbax), printed as one line advising to free space and resume.
DISK_ERRNOS = {
    errno.ENOSPC: "free some space",
    errno.EDQUOT: "free some space (disk quota)",
    errno.EROFS: "choose a writable location",
}


def disk_error(err: BaseException) -> OSError | None:
    """The full-disk or read-only-disk :class:`OSError` behind ``err`` (its cause chain), or None."""
    seen = set()
    while err is not None and id(err) not in seen:
        seen.add(id(err))
        if isinstance(err, OSError) and err.errno in DISK_ERRNOS:
            return err
        err = err.__cause__ or err.__context__
    return None


def expected_error_types(
    extra: Iterable[type[BaseException]] = (),
) -> tuple[type[BaseException], ...]:
    """The expected exception classes of the modules imported so far, path errors and ``extra``."""
    found = []
    for module, name in EXPECTED_ERRORS:
        cls = getattr(sys.modules.get(module), name, None)
        if isinstance(cls, type) and issubclass(cls, BaseException):
            found.append(cls)
    return (UsageError, *found, *PATH_ERRORS, *extra)


def positive_int(option: str, value: int) -> int:
    """``value`` if it is >= 1, else a :class:`UsageError` naming ``option``."""
    if value < 1:
        raise UsageError(f"{option} {value}: expected a positive integer (1 or more)")
    return value


SEED_MAX = 2**32 - 1  # jax.random.key takes a 32-bit seed (larger values wrap or overflow)


def seed_arg(text: str) -> int:
    """An argparse ``type`` for a PRNG seed: an integer in ``[0, 2**32 - 1]``."""
    import argparse

    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if not 0 <= value <= SEED_MAX:
        raise argparse.ArgumentTypeError(f"must be in [0, {SEED_MAX}], got {text}")
    return value


def check_writable(path: str | os.PathLike, flag: str) -> None:
    """A :class:`UsageError` unless a file can be written at ``path`` (its folder is created on
    write), so a script can refuse an output path before doing its work."""
    from ntq_jax.artifacts import unwritable_reason

    path = Path(path)
    if path.is_dir():
        raise UsageError(f"{flag} {path} is a folder; give a file name")
    why = unwritable_reason(path.parent)
    if why:
        raise UsageError(f"{flag} {path} cannot be written: {why}")


def check_writable_folder(path: str | os.PathLike, flag: str) -> None:
    """A :class:`UsageError` unless ``path`` is (or can be created as) a folder files can be
    written in, so a script can refuse an output folder before doing its work."""
    from ntq_jax.artifacts import unwritable_reason

    path = Path(path)
    why = (
        f"{path} is a file, not a folder"
        if path.exists() and not path.is_dir()
        else unwritable_reason(path)
    )
    if why:
        raise UsageError(f"{flag} {path} cannot be written: {why}; give a writable folder")


def add_run_options(
    ap,
    *,
    set_example: str,
    figures_help: str | None,
    cpu_devices_help: str,
    executor: bool = False,
    config_help: str | None = None,
) -> None:
    """The options of every script that runs pipeline stages: ``--config``, ``--set``,
    ``--no-progress``, ``--no-compile-cache``, ``--cpu-devices`` (applied by
    :func:`start_run`), ``--no-figures`` unless ``figures_help`` is None and, with
    ``executor``, ``--executor`` and ``--ray-address`` (:func:`executor_of`)."""
    ap.add_argument(
        "--config", default=None, help=config_help or "YAML config (default: the embedded default)"
    )
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help=f"config override, e.g. --set {set_example} (repeatable)",
    )
    ap.add_argument("--no-progress", action="store_true", help="no progress bars")
    ap.add_argument(
        "--no-compile-cache",
        action="store_true",
        help="do not use JAX's persistent compilation cache",
    )
    if figures_help is not None:
        ap.add_argument("--no-figures", action="store_true", help=figures_help)
    ap.add_argument("--cpu-devices", type=int, default=1, help=cpu_devices_help)
    if executor:
        add_executor_options(ap)


def add_executor_options(ap) -> None:
    """``--executor local|ray`` and ``--ray-address`` (read by :func:`executor_of`)."""
    ap.add_argument(
        "--executor",
        choices=("local", "ray"),
        default=None,
        help="where the planning chunks run: local (this process, the default) or "
        "ray (Ray tasks; overrides the config's executor)",
    )
    ap.add_argument(
        "--ray-address",
        default=None,
        metavar="ADDRESS",
        help="with --executor ray: auto joins the cluster `ray start` made, "
        "<host>:<port> another one; default: start a local Ray instance",
    )


def executor_of(args, cfg):
    """The executor of ``cfg`` with :func:`add_executor_options`' options overriding it."""
    from ntq_jax.executors import make_executor

    name = getattr(args, "executor", None) or cfg.executor or "local"
    address = getattr(args, "ray_address", None)
    if address and name != "ray":
        raise UsageError("--ray-address needs --executor ray (or executor: ray in the config)")
    return make_executor(name, address if address is not None else cfg.ray_address)


def start_run(args) -> None:
    """Applies :func:`add_run_options`' ``--cpu-devices`` (before any JAX operation) and
    ``--no-compile-cache``."""
    from ntq_jax import artifacts
    from ntq_jax.training import use_cpu_devices

    use_cpu_devices(positive_int("--cpu-devices", args.cpu_devices))
    if not args.no_compile_cache:
        artifacts.enable_compile_cache()


def error_line(err: BaseException) -> str:
    """``error: <message>`` on one line (a multi-line message is joined with ``; ``).

    A path error without a message of ours (``[Errno 13] Permission denied:
    'x'``) becomes ``<path>: <reason>; <fix>``.
    """
    disk = disk_error(err)
    if disk is not None:
        where = f"{disk.filename}: " if disk.filename is not None else ""
        reason = (disk.strerror or os.strerror(disk.errno)).lower()
        return (
            f"error: {where}{reason}; {DISK_ERRNOS[disk.errno]} and run the same command "
            "again (a run resumes from its last finished step)"
        )
    fix = next((f for cls, f in PATH_ERRORS.items() if type(err) is cls), None)
    if fix is not None and isinstance(err, OSError) and err.strerror:
        where = f"{err.filename}: " if err.filename is not None else ""
        msg = f"{where}{err.strerror.lower()}; {fix}"
    else:
        msg = str(err) or type(err).__name__
    parts = [p.strip() for p in msg.splitlines() if p.strip()]
    return "error: " + "; ".join(parts)


def _quiet_asyncio_after_error() -> None:
    """Silences asyncio's "Event loop is closed" noise printed at exit after a failed orbax read."""
    logging.getLogger("asyncio").setLevel(logging.CRITICAL)
    logging.getLogger("absl").setLevel(logging.CRITICAL)

    def hook(unraisable, _default=sys.unraisablehook):
        exc = unraisable.exc_value
        if isinstance(exc, RuntimeError) and "Event loop is closed" in str(exc):
            return
        _default(unraisable)

    sys.unraisablehook = hook


def run_cli(main: Callable[[], int], extra: Iterable[type[BaseException]] = ()) -> int:
    """Runs a script's ``main()`` and returns its exit code; expected errors become one line.

    Args:
        main: the script's body, returning its exit code.
        extra: more exception classes the script expects (printed the same way).

    Returns:
        ``main()``'s exit code; 2 after an expected error (one ``error: ...``
        line on stderr), 130 after Ctrl-C. Other exceptions propagate with
        their traceback.
    """
    try:
        return main()
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except Exception as e:  # noqa: BLE001 (re-raised unless expected)
        if not isinstance(e, expected_error_types(extra)) and disk_error(e) is None:
            raise
        _quiet_asyncio_after_error()
        print(error_line(e), file=sys.stderr, flush=True)
        return 2
