"""Environments: a robot in a world of obstacles, and their names.

* :mod:`ntq_jax.envs.env`: :class:`Env` (``is_valid``, ``steer_to``, ``distance``,
  ``sample_queries``, ``gamma_nt``, JSON round trip).
* :mod:`ntq_jax.envs.make`: :func:`make_env` (presets, Panda problems, map files).
* :mod:`ntq_jax.envs.names`: :func:`env_slug` (an environment's folder) and
  :func:`resolve_envs` (a config's ``envs`` list, each map once).
"""

from ntq_jax.envs.env import (
    BUCKET_MIN_ROWS,
    MAX_STATES_PER_MOTION,
    Env,
    EnvError,
    check_resolution,
    index_reach,
)
from ntq_jax.envs.make import make_env, panda_env
from ntq_jax.envs.names import env_slug, resolve_envs

__all__ = [
    "Env",
    "EnvError",
    "make_env",
    "panda_env",
    "check_resolution",
    "index_reach",
    "MAX_STATES_PER_MOTION",
    "BUCKET_MIN_ROWS",
    "env_slug",
    "resolve_envs",
]
