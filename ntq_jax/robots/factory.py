"""Builds a robot from the ``robot`` object of the environment JSON."""

from __future__ import annotations

import dataclasses

from ntq_jax.robots.base import Robot
from ntq_jax.robots.nlink import NLinkArm
from ntq_jax.robots.point import PointRobot
from ntq_jax.robots.rigid_body import RigidBody
from ntq_jax.robots.serial_arm import DEFAULT_RESOLUTION, SerialArm
from ntq_jax.validation import number, short_repr

_KINDS = {"point": PointRobot, "rigid_body": RigidBody, "nlink": NLinkArm, "serial_arm": SerialArm}
#: The parameters of a ``serial_arm``: a preset (``"panda"``), or a URDF (and an SRDF's
#: disabled collision pairs) with the chain's tip link; and the discretised check's resolution.
SERIAL_ARM_KEYS = ("preset", "urdf", "srdf", "tip", "resolution")
SERIAL_ARM_PRESETS = ("panda",)


def _serial_arm(params: dict, where: str) -> SerialArm:
    """``{"preset": "panda"}`` or ``{"urdf": path, "srdf": path, "tip": link}``, each with an
    optional ``resolution`` (radians; default 1/32). Paths are taken as given (relative
    to the working directory)."""
    unknown = sorted(set(params) - set(SERIAL_ARM_KEYS))
    if unknown:
        raise ValueError(
            f"{where}: unknown parameter(s) {unknown} for kind 'serial_arm'; "
            f"allowed: {list(SERIAL_ARM_KEYS)}"
        )
    resolution = number(
        params.get("resolution", DEFAULT_RESOLUTION), f"{where}.resolution", minimum=0, strict=True
    )
    if "preset" in params:
        if set(params) - {"preset", "resolution"}:
            raise ValueError(f"{where}: a serial_arm preset takes only 'resolution' beside it")
        if params["preset"] not in SERIAL_ARM_PRESETS:
            raise ValueError(
                f"{where}.preset {short_repr(params['preset'])} is unknown; use one "
                f"of {list(SERIAL_ARM_PRESETS)} or give 'urdf' (and 'srdf', 'tip')"
            )
        return SerialArm.panda(resolution)
    if not isinstance(params.get("urdf"), str):
        raise ValueError(
            f"{where}: a serial_arm needs 'preset' or 'urdf' (the path of a URDF "
            f"file), got {short_repr(params.get('urdf'))}"
        )
    for key in ("srdf", "tip"):
        if params.get(key) is not None and not isinstance(params[key], str):
            raise ValueError(f"{where}.{key} must be a string, got {short_repr(params[key])}")
    return SerialArm.from_urdf(params["urdf"], params.get("srdf"), params.get("tip"), resolution)


def robot_from_json(spec: dict, where: str = "robot") -> Robot:
    """Builds a robot from its JSON description ``{"kind": ..., **params}``.

    Raises:
        ValueError: unknown kind or parameter (naming the accepted ones), or a bad
            parameter value (naming the parameter and the expected form; e.g.
            ``link_lengths`` must be a list of numbers, never a string).
    """
    if not isinstance(spec, dict) or "kind" not in spec:
        raise ValueError(
            f"{where} must be an object with a 'kind' in {sorted(_KINDS)}, got {short_repr(spec)}"
        )
    kind = spec["kind"]
    if not isinstance(kind, str) or kind not in _KINDS:
        raise ValueError(f"{where}.kind {kind!r} is unknown; use one of {sorted(_KINDS)}")
    cls = _KINDS[kind]
    params = {k: v for k, v in spec.items() if k != "kind"}
    if cls is SerialArm:
        try:
            return _serial_arm(params, where)
        except (TypeError, ValueError, OSError) as e:
            msg = str(e)
            raise ValueError(msg if msg.startswith(where) else f"{where}: {msg}") from None
    allowed = {f.name for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(params) - allowed)
    if unknown:
        raise ValueError(
            f"{where}: unknown parameter(s) {unknown} for kind {kind!r}; allowed: {sorted(allowed)}"
        )
    try:
        return cls(**params)  # each robot's __post_init__ checks its parameters strictly
    except (TypeError, ValueError) as e:
        raise ValueError(f"{where}: {e}") from None
