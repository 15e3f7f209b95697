"""ROS messages to arrays, pure and duck-typed: the same field names on rclpy's message objects and on
rosbags' typestore objects, so a live subscription and a bag decode alike. No ROS import here.

``sensor_msgs/JointState``: ``name[]``, ``position[]`` (rad or m), ``velocity[]`` (rad/s), ``effort[]`` (what
the driver puts there: ur_robot_driver the joint current, A; franka_ros2 the measured torque tau_J, N m);
each array as long as ``name`` or empty (the message's own rule). Joints are matched **by name**, never by
position: ros2_control's joint_state_broadcaster orders them as its map does, not as the robot
description. ``geometry_msgs/WrenchStamped``: ``wrench.force`` N and ``wrench.torque`` N m in
``header.frame_id``. ``std_msgs/Header.stamp``: ``sec`` and ``nanosec``.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

EFFORT_KINDS = ("current", "torque", "none")


class RosInputError(ValueError):
    """A message that cannot be read as the scene's frame (the message says why): not used, counted."""


class JointNamesError(RosInputError):
    """The message's joint names do not hold the scene's joints (missing or repeated names)."""


class FrameIdError(RosInputError):
    """A wrench in another frame than the one the scene's sensor is."""


def stamp_ns(header: Any) -> int:
    """``header.stamp`` as integer ns (``sec`` may be negative before 1970 only in odd clocks: kept)."""
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def joint_index(names: Sequence[str], wanted: Sequence[str]) -> np.ndarray:
    """Where each of ``wanted`` (the scene's order, message names) is in ``names`` (the message's), as an
    index array (n_wanted,). JointNamesError names the missing and repeated ones; names the scene does not
    want (a gripper's fingers) are left out, never mixed in."""
    where: dict[str, int] = {}
    repeated = []
    for i, n in enumerate(names):
        if n in where:
            repeated.append(n)
        where[n] = i
    missing = [w for w in wanted if w not in where]
    if missing or repeated:
        what = "; ".join(p for p in (
            f"no joint {', '.join(missing)}" if missing else "",
            f"joint {', '.join(repeated)} named twice" if repeated else "") if p)
        raise JointNamesError(f"{what} (the message names: {', '.join(names) or 'none'}; the scene's joints are "
                              "mapped by the device's joints or joint_prefix params)")
    return np.fromiter((where[w] for w in wanted), dtype=np.intp, count=len(wanted))


def extra_joints(names: Sequence[str], wanted: Sequence[str]) -> list[str]:
    """The message's joints the scene does not map (left out of its frames)."""
    keep = set(wanted)
    return [n for n in names if n not in keep]


def _field(msg: Any, field: str, n: int, required: bool) -> np.ndarray | None:
    values = np.asarray(getattr(msg, field), dtype=float)
    if values.size == 0 and not required:
        return None
    if values.shape != (n,):
        raise RosInputError(f"{field} has {values.size} values for {n} joint names")
    return values


def joint_arrays(msg: Any, index: np.ndarray, *, effort: str) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """``(q, qd, effort)`` of a JointState in the scene's order (``index``: :func:`joint_index`); effort None
    with ``effort="none"``. Values are as sent (NaN included: the caller judges them); RosInputError on an
    array whose length is not the names' or a missing position, velocity or wanted effort."""
    if effort not in EFFORT_KINDS:
        raise ValueError(f"effort: expected one of {', '.join(EFFORT_KINDS)}, got {effort!r}")
    n = len(msg.name)
    q = _field(msg, "position", n, True)
    qd = _field(msg, "velocity", n, True)
    eff = None if effort == "none" else _field(msg, "effort", n, True)
    assert q is not None and qd is not None
    return q[index], qd[index], None if eff is None else eff[index]


def non_finite(**arrays: np.ndarray | None) -> list[str]:
    """The names of the arrays holding NaN or Inf (ros2_control sends NaN for an interface it lacks)."""
    return [name for name, a in arrays.items() if a is not None and not np.all(np.isfinite(a))]


def wrench_array(msg: Any) -> np.ndarray:
    """A WrenchStamped's (or Wrench's) ``[fx, fy, fz, tx, ty, tz]``, (6,), N and N m."""
    w = getattr(msg, "wrench", msg)
    f, t = w.force, w.torque
    return np.array([f.x, f.y, f.z, t.x, t.y, t.z], dtype=float)


def check_frame(msg: Any, expected: str) -> None:
    """FrameIdError unless the message's ``header.frame_id`` is ``expected``."""
    got = msg.header.frame_id
    if got != expected:
        raise FrameIdError(f"wrench in frame {got!r}, not the scene's sensor frame {expected!r} (set the device's "
                           "frame_id param to the driver's frame if it is the sensor's)")
