"""Lazy package attributes (PEP 562): a package's public names load on first use.

Imports only the standard library, so a process that needs one JAX-free module of the
package (a BIT* worker: :mod:`ntq_jax.planners.ompl_worker`) does not load JAX through
the package ``__init__`` modules on the way.
"""

from __future__ import annotations

import importlib
from typing import Callable


def lazy_exports(
    package: str, namespace: dict, exports: dict[str, str]
) -> tuple[Callable[[str], object], Callable[[], list[str]]]:
    """``(__getattr__, __dir__)`` for the package ``package`` whose globals are ``namespace``.

    ``exports`` maps each public name to the module it lives in. Any other name is tried
    as a submodule (``package.name``). A loaded value is stored in ``namespace``, so each
    name is looked up once.

    Raises (from ``__getattr__``):
        AttributeError: the name is neither an export nor a submodule.
    """

    def getattr_(name: str):
        if name in exports:
            value = getattr(importlib.import_module(exports[name]), name)
        else:
            try:
                value = importlib.import_module(f"{package}.{name}")
            except ModuleNotFoundError as e:
                if e.name != f"{package}.{name}":
                    raise
                raise AttributeError(f"module {package!r} has no attribute {name!r}") from None
        namespace[name] = value
        return value

    def dir_() -> list[str]:
        return sorted(set(namespace) | set(exports))

    return getattr_, dir_
