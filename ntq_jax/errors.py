"""Exceptions shared by the library and its command lines (the ground floor: imports nothing).

Expected failures of the library raise their own exceptions where they arise
(``ConfigError``, ``EnvError``, ``DatasetError``, ...); :class:`UsageError` is
the one for an argument a caller cannot use, raised by library code that
parses user input (e.g. the learning curve's ``--sizes``) as well as by the
scripts. :func:`ntq_jax.cli.run_cli` prints each as one ``error:`` line.
"""

from __future__ import annotations

__all__ = ["UsageError"]


class UsageError(ValueError):
    """A command-line argument that cannot be used (the message names the option and the fix)."""
