"""ROS messages to arrays, duck-typed: the same functions take rclpy's messages and rosbags' typestore
messages (both have the fields by the message definition's names). Pure: no ROS import."""
from __future__ import annotations

import numpy as np


def stamp_ns(header) -> int:
    """A ``std_msgs/Header``'s stamp (``builtin_interfaces/Time``) in ns."""
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def joint_state_arrays(msg, index: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A ``sensor_msgs/JointState``'s position, velocity and effort at ``index`` (the message's position of
    each wanted joint), as float arrays; an empty field (the message's convention for "not published")
    comes back as an empty array. Raises IndexError when a field is shorter than ``index`` needs."""
    out = []
    for field in (msg.position, msg.velocity, msg.effort):
        values = np.asarray(field, dtype=float)
        out.append(values[index] if values.size else np.zeros(0))
    return out[0], out[1], out[2]


def joint_index(msg_names, wanted: list[str]) -> list[int] | None:
    """Where each of ``wanted`` sits in a JointState's ``name`` list; None when one of them is not there."""
    where = {n: i for i, n in enumerate(msg_names)}
    try:
        return [where[n] for n in wanted]
    except KeyError:
        return None


def wrench_array(msg) -> np.ndarray:
    """A ``geometry_msgs/WrenchStamped`` as [fx, fy, fz, tx, ty, tz] (N, N m, in ``header.frame_id``)."""
    f, t = msg.wrench.force, msg.wrench.torque
    return np.array([f.x, f.y, f.z, t.x, t.y, t.z], dtype=float)
