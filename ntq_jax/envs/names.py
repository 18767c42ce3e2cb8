"""Names of environments: the folder of each (:func:`env_slug`), and a config's list of them (:func:`resolve_envs`)."""

from __future__ import annotations

import functools
import re
from pathlib import Path

from ntq_jax.envs.env import Env, EnvError
from ntq_jax.envs.make import make_env
from ntq_jax.presets import PRESETS

__all__ = ["env_slug", "resolve_envs"]


@functools.cache
def _preset_hash(name: str) -> str:
    """:meth:`Env.content_hash` of the preset ``name``."""
    return make_env(name).content_hash()


def env_slug(name: str, env: Env | None = None) -> str:
    """Folder name of an environment: readable, and unique to the environment's content.

    A preset keeps its readable name, ``'point/0' -> 'point_0'``. Every other
    environment (a map file, or an ``env`` that is not the named preset) gets its
    readable name plus the first 8 hex digits of :meth:`Env.content_hash`:
    ``'maps/a.json' -> 'a-3f2c9e1b'``. So two different maps never share a
    folder (``a/map.json`` and ``b/map.json`` get two), and the same map under
    two paths with the same file name is one folder.

    Args:
        name: the name in ``config.envs`` (a preset or a map file path), or ``env.name``.
        env: the environment ``name`` stands for; default ``make_env(name)`` (reads
            the map file; raises :class:`~ntq_jax.envs.EnvError` if it cannot).
    """
    s = str(name)
    readable = Path(s).stem if s.lower().endswith((".json", ".yaml", ".yml", ".map")) else s
    readable = re.sub(r"[^A-Za-z0-9_.-]+", "_", readable).strip("_.-") or "env"
    if s in PRESETS and (env is None or env.content_hash() == _preset_hash(s)):
        return readable
    env = make_env(s) if env is None else env
    return f"{readable}-{env.content_hash()[:8]}"


def resolve_envs(names) -> dict[str, Env]:
    """``{name: Env}`` for the names of ``config.envs``, each in a folder of its own.

    Builds every environment first (so a bad name or map file fails before
    anything is written) and refuses two names that would share a folder
    (:func:`env_slug`) or that are the same map under two names.

    Raises:
        EnvError: a bad name or map file, or duplicates (listing them).
    """
    names = [str(n) for n in names]
    envs = {n: make_env(n) for n in names}
    by_slug: dict[str, list[str]] = {}
    by_content: dict[str, list[str]] = {}
    for name in names:
        by_slug.setdefault(env_slug(name, envs[name]), []).append(name)
        by_content.setdefault(envs[name].content_hash(), []).append(name)
    same = [(f"would share the folder {slug!r}", ns) for slug, ns in by_slug.items() if len(ns) > 1]
    same += [
        (f"the same map, content hash {h[:8]}", ns)
        for h, ns in by_content.items()
        if len({env_slug(n, envs[n]) for n in ns}) > 1
    ]
    if same:
        listed = "; ".join(f"{', '.join(map(repr, ns))} ({what})" for what, ns in same)
        raise EnvError(
            f"envs lists the same environment more than once: {listed}; list each map once"
        )
    return envs
