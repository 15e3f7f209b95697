"""The robot description a version-10 controller (FR3 system) serves on GetRobotModel: a URDF whose
seven joints carry what libfranka 0.21 reads from it (``src/joint_velocity_limits.cpp``): each joint
named ``...jointN``, a ``<limit lower upper velocity>`` and a ``<position_based_velocity_limits
velocity_offset deceleration_limit>``; a robot name not starting with ``tmr`` (a mobile robot's).

Joint ranges: the scene's model. Velocity and effort limits: Franka's FR3 datasheet ("Franka Research
3, robot and interface specifications": 2.62 rad/s joints 1-4, 5.26 / 4.18 / 5.26 rad/s joints 5-7;
87 N m joints 1-4, 12 N m joints 5-7). velocity_offset and deceleration_limit: ESTIMATE (not in the
datasheet): libfranka uses them only to limit commanded velocities near the joint limits, which the
emulator does not take.
"""
from __future__ import annotations

from xml.sax.saxutils import quoteattr

import numpy as np

VELOCITY = (2.62, 2.62, 2.62, 2.62, 5.26, 4.18, 5.26)  # rad/s, FR3 datasheet
EFFORT = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)  # N m, FR3 datasheet
VELOCITY_OFFSET = 0.3  # rad/s, ESTIMATE
DECELERATION = 10.0  # rad/s^2, ESTIMATE


def robot_urdf(name: str, lower: np.ndarray, upper: np.ndarray) -> str:
    """The description of a 7-joint arm with the given joint ranges (rad)."""
    joints = "".join(
        f'<joint name="fr3_joint{i + 1}" type="revolute">'
        f'<limit lower="{lower[i]:.6f}" upper="{upper[i]:.6f}" velocity="{VELOCITY[i]}" effort="{EFFORT[i]}"/>'
        f'<position_based_velocity_limits velocity_offset="{VELOCITY_OFFSET}" deceleration_limit="{DECELERATION}"/>'
        "</joint>" for i in range(7))
    return f"<?xml version=\"1.0\"?><robot name={quoteattr(name)}>{joints}</robot>"
