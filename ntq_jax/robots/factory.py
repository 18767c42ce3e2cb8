"""Builds a robot from the ``robot`` object of the environment JSON."""

from __future__ import annotations

import dataclasses

from ntq_jax.robots.base import Robot
from ntq_jax.robots.nlink import NLinkArm
from ntq_jax.robots.point import PointRobot
from ntq_jax.robots.rigid_body import RigidBody

_KINDS = {"point": PointRobot, "rigid_body": RigidBody, "nlink": NLinkArm}


def robot_from_json(spec: dict, where: str = "robot") -> Robot:
    """Builds a robot from its JSON description ``{"kind": ..., **params}``.

    Raises:
        ValueError: unknown kind or parameter, naming the accepted ones.
    """
    if not isinstance(spec, dict) or "kind" not in spec:
        raise ValueError(f"{where} must be an object with a 'kind' in {sorted(_KINDS)}")
    kind = spec["kind"]
    if kind not in _KINDS:
        raise ValueError(f"{where}.kind {kind!r} is unknown; use one of {sorted(_KINDS)}")
    cls = _KINDS[kind]
    params = {k: v for k, v in spec.items() if k != "kind"}
    allowed = {f.name for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(params) - allowed)
    if unknown:
        raise ValueError(f"{where}: unknown parameter(s) {unknown} for kind {kind!r}; "
                         f"allowed: {sorted(allowed)}")
    if kind == "nlink":
        params = {k: tuple(v) if isinstance(v, list) else v for k, v in params.items()}
    return cls(**params)
