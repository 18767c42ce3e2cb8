"""Exceptions shared by the library and its command lines (the ground floor: imports nothing).

Expected failures of the library raise their own exceptions where they arise
(``ConfigError``, ``EnvError``, ``DatasetError``, ...); :class:`UsageError` is
the one for an argument a caller cannot use, raised by library code that
parses user input (e.g. the learning curve's ``--sizes``) as well as by the
scripts. :func:`ntq_jax.experiment.cli.run_cli` prints each as one ``error:`` line.
"""

from __future__ import annotations

__all__ = ["UsageError", "ConfigError", "check_config"]


class UsageError(ValueError):
    """A command-line argument that cannot be used (the message names the option and the fix)."""


class ConfigError(ValueError):
    """A configuration problem, naming the file and the key."""


def check_config(cond: bool, key: str, msg: str) -> None:
    """Raise ``ConfigError("<key>: <msg>")`` unless ``cond``."""
    if not cond:
        raise ConfigError(f"{key}: {msg}")
