"""Robots: point (R^2), rigid body (SE(2)) and planar n-link arm (re-exports only)."""

from ntq_jax.robots.base import (
    DiscretizedSteering,
    Robot,
    discretized_steer_to,
    discretized_steer_to_batch,
    wrap_angle,
)
from ntq_jax.robots.factory import robot_from_json
from ntq_jax.robots.nlink import NLinkArm
from ntq_jax.robots.point import PointRobot
from ntq_jax.robots.rigid_body import RigidBody
from ntq_jax.robots.serial_arm import SerialArm

__all__ = [
    "Robot",
    "PointRobot",
    "RigidBody",
    "NLinkArm",
    "SerialArm",
    "robot_from_json",
    "DiscretizedSteering",
    "discretized_steer_to",
    "discretized_steer_to_batch",
    "wrap_angle",
]
