"""Per-environment caches of what a planner builds once (occupancy grids, visibility graphs).

An :class:`EnvCache` holds its entries only while their environment is alive
(weak keys, by identity) and keeps at most ``per_env`` settings per
environment (least recently used dropped), so a cache never keeps an
environment, or an unbounded number of built objects, alive. A cached value
must not refer to its environment (store ``env.robot`` / ``env.world``
instead), or the environment would never be released.
"""

from __future__ import annotations

import collections
import weakref
from typing import Callable, Hashable, TypeVar

T = TypeVar("T")

__all__ = ["EnvCache"]


class EnvCache:
    """``get(env, key, build)``: ``build()`` once per (environment, settings key)."""

    def __init__(self, per_env: int = 4):
        if per_env < 1:
            raise ValueError(f"per_env must be >= 1, got {per_env}")
        self._per_env = int(per_env)
        self._entries: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()

    def get(self, env, key: Hashable, build: Callable[[], T]) -> T:
        """The value cached for ``(env, key)``, built by ``build()`` on a miss."""
        entries = self._entries.get(env)
        if entries is None:
            entries = self._entries[env] = collections.OrderedDict()
        if key in entries:
            entries.move_to_end(key)
            return entries[key]
        value = entries[key] = build()
        while len(entries) > self._per_env:
            entries.popitem(last=False)
        return value

    def clear(self) -> None:
        """Drops every entry."""
        self._entries.clear()
