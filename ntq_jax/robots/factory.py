"""Builds a robot from the ``robot`` object of the environment JSON."""

from __future__ import annotations

import dataclasses

from ntq_jax.robots.base import Robot
from ntq_jax.robots.nlink import NLinkArm
from ntq_jax.robots.point import PointRobot
from ntq_jax.robots.rigid_body import RigidBody
from ntq_jax.validation import short_repr

_KINDS = {"point": PointRobot, "rigid_body": RigidBody, "nlink": NLinkArm}


def robot_from_json(spec: dict, where: str = "robot") -> Robot:
    """Builds a robot from its JSON description ``{"kind": ..., **params}``.

    Raises:
        ValueError: unknown kind or parameter (naming the accepted ones), or a bad
            parameter value (naming the parameter and the expected form; e.g.
            ``link_lengths`` must be a list of numbers, never a string).
    """
    if not isinstance(spec, dict) or "kind" not in spec:
        raise ValueError(f"{where} must be an object with a 'kind' in {sorted(_KINDS)}, got "
                         f"{short_repr(spec)}")
    kind = spec["kind"]
    if not isinstance(kind, str) or kind not in _KINDS:
        raise ValueError(f"{where}.kind {kind!r} is unknown; use one of {sorted(_KINDS)}")
    cls = _KINDS[kind]
    params = {k: v for k, v in spec.items() if k != "kind"}
    allowed = {f.name for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(params) - allowed)
    if unknown:
        raise ValueError(f"{where}: unknown parameter(s) {unknown} for kind {kind!r}; "
                         f"allowed: {sorted(allowed)}")
    try:
        return cls(**params)  # each robot's __post_init__ checks its parameters strictly
    except (TypeError, ValueError) as e:
        raise ValueError(f"{where}: {e}") from None
