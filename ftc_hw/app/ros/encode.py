"""ROS 2 messages as CDR bytes: one encoder for what ``ftc monitor --ros`` publishes (rclpy publishers take
the bytes) and what the ROS 2 bag holds (written as they are).

Messages are rosbags' typestore classes (ROS 2 Kilted's definitions, tf2_msgs included) serialized with
``Typestore.serialize_cdr``: the CDR rclpy makes (its padding bytes aside, which rclpy leaves unset), the
type hashes its wheels carry. The one message of every judged frame, ``WrenchStamped``, is packed directly
(1 us against rosbags' 50 and rclpy's 80 per message, measured on this 2-core host): tested equal, byte for
byte, to rosbags' encoding.
"""
from __future__ import annotations

import struct
from functools import cache
from typing import Any

import numpy as np
from rosbags.typesys import Stores, get_typestore

CDR_LE = b"\x00\x01\x00\x00"  # the encapsulation header: plain CDR, little endian
# visualization_msgs/Marker's constants
ARROW, CUBE, SPHERE, CYLINDER, TEXT_VIEW_FACING = 0, 1, 2, 3, 9
ADD, DELETEALL = 0, 3
# diagnostic_msgs/DiagnosticStatus's levels
OK, WARN, ERROR, STALE = 0, 1, 2, 3


@cache
def typestore() -> Any:
    return get_typestore(Stores.ROS2_KILTED)


def msg(name: str) -> Any:
    """The typestore's class of ``pkg/msg/Name``."""
    return typestore().types[name]


def serialize(message: Any) -> bytes:
    return bytes(typestore().serialize_cdr(message, message.__msgtype__))


def stamp(t_ns: int) -> Any:
    t = int(t_ns)
    return msg("builtin_interfaces/msg/Time")(sec=t // 1_000_000_000, nanosec=t % 1_000_000_000)


def header(t_ns: int, frame_id: str) -> Any:
    return msg("std_msgs/msg/Header")(stamp=stamp(t_ns), frame_id=frame_id)


def vector3(v) -> Any:
    return msg("geometry_msgs/msg/Vector3")(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def point(v) -> Any:
    return msg("geometry_msgs/msg/Point")(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def quaternion(xyzw=(0.0, 0.0, 0.0, 1.0)) -> Any:
    x, y, z, w = (float(c) for c in xyzw)
    return msg("geometry_msgs/msg/Quaternion")(x=x, y=y, z=z, w=w)


def pose(position, xyzw=(0.0, 0.0, 0.0, 1.0)) -> Any:
    return msg("geometry_msgs/msg/Pose")(position=point(position), orientation=quaternion(xyzw))


def quat_xyzw(rotation: np.ndarray) -> tuple[float, float, float, float]:
    """A rotation matrix as ROS's quaternion (x, y, z, w), w >= 0."""
    r = np.asarray(rotation, dtype=float)
    w = 0.5 * np.sqrt(max(0.0, 1.0 + r[0, 0] + r[1, 1] + r[2, 2]))
    x = 0.5 * np.sqrt(max(0.0, 1.0 + r[0, 0] - r[1, 1] - r[2, 2]))
    y = 0.5 * np.sqrt(max(0.0, 1.0 - r[0, 0] + r[1, 1] - r[2, 2]))
    z = 0.5 * np.sqrt(max(0.0, 1.0 - r[0, 0] - r[1, 1] + r[2, 2]))
    x, y, z = np.copysign(x, r[2, 1] - r[1, 2]), np.copysign(y, r[0, 2] - r[2, 0]), np.copysign(z, r[1, 0] - r[0, 1])
    n = float(np.sqrt(w * w + x * x + y * y + z * z))
    return float(x / n), float(y / n), float(z / n), float(w / n)


# -- WrenchStamped, packed directly (every judged frame) ---------------------------------------------------
@cache
def _wrench_prefix(frame_id: str) -> tuple[bytes, bytes]:
    """What follows the stamp: the frame id (length, bytes, NUL) and the padding before the doubles."""
    fid = frame_id.encode() + b"\x00"
    pad = (-(12 + len(fid))) % 8  # the doubles align to 8 from the end of the encapsulation header
    return struct.pack("<I", len(fid)) + fid, b"\x00" * pad


_STAMP = struct.Struct("<iI")
_SIX = struct.Struct("<6d")


def wrench_stamped(t_ns: int, frame_id: str, wrench) -> bytes:
    """``geometry_msgs/WrenchStamped``: ``wrench`` [fx, fy, fz, tx, ty, tz] (N, N m) in ``frame_id``."""
    t = int(t_ns)
    fid, pad = _wrench_prefix(frame_id)
    return b"".join((CDR_LE, _STAMP.pack(t // 1_000_000_000, t % 1_000_000_000), fid, pad,
                     _SIX.pack(*(float(x) for x in wrench))))


def wrench_stamped_typestore(t_ns: int, frame_id: str, wrench) -> bytes:
    """The same message through rosbags (the reference the packed one is tested against)."""
    w = msg("geometry_msgs/msg/Wrench")(force=vector3(wrench[:3]), torque=vector3(wrench[3:]))
    return serialize(msg(EXTERNAL)(header=header(t_ns, frame_id), wrench=w))


EXTERNAL = "geometry_msgs/msg/WrenchStamped"


# -- the other messages ------------------------------------------------------------------------------------
def pose_stamped(t_ns: int, frame_id: str, position, xyzw=(0.0, 0.0, 0.0, 1.0)) -> bytes:
    return serialize(msg("geometry_msgs/msg/PoseStamped")(header=header(t_ns, frame_id), pose=pose(position, xyzw)))


def transform_stamped(t_ns: int, parent: str, child: str, position, xyzw) -> Any:
    tf = msg("geometry_msgs/msg/Transform")(translation=vector3(position), rotation=quaternion(xyzw))
    return msg("geometry_msgs/msg/TransformStamped")(header=header(t_ns, parent), child_frame_id=child, transform=tf)


def tf_message(transforms: list[Any]) -> bytes:
    return serialize(msg("tf2_msgs/msg/TFMessage")(transforms=transforms))


def string(text: str) -> bytes:
    return serialize(msg("std_msgs/msg/String")(data=text))


def joint_state(t_ns: int, names: tuple[str, ...], position, velocity, effort) -> bytes:
    arr = [np.asarray(v, dtype=np.float64) for v in (position, velocity, effort)]
    return serialize(msg("sensor_msgs/msg/JointState")(header=header(t_ns, ""), name=list(names), position=arr[0],
                                                        velocity=arr[1], effort=arr[2]))


def color(r: float, g: float, b: float, a: float = 1.0) -> Any:
    return msg("std_msgs/msg/ColorRGBA")(r=float(r), g=float(g), b=float(b), a=float(a))


def marker(t_ns: int, frame_id: str, ns: str, mid: int, kind: int, *, position=(0.0, 0.0, 0.0),
           xyzw=(0.0, 0.0, 0.0, 1.0), scale=(1.0, 1.0, 1.0), rgba=(1.0, 1.0, 1.0, 1.0), lifetime_s: float = 0.0,
           points: tuple = (), text: str = "", action: int = ADD) -> Any:
    """A ``visualization_msgs/Marker`` (lifetime 0: until replaced or deleted)."""
    life = round(lifetime_s * 1e9)
    return msg("visualization_msgs/msg/Marker")(
        header=header(t_ns, frame_id), ns=ns, id=int(mid), type=kind, action=action, pose=pose(position, xyzw),
        scale=vector3(scale), color=color(*rgba),
        lifetime=msg("builtin_interfaces/msg/Duration")(sec=life // 1_000_000_000, nanosec=life % 1_000_000_000),
        frame_locked=False, points=[point(p) for p in points], colors=[], texture_resource="",
        texture=msg("sensor_msgs/msg/CompressedImage")(header=header(0, ""), format="", data=np.zeros(0, np.uint8)),
        uv_coordinates=[], text=text, mesh_resource="",
        mesh_file=msg("visualization_msgs/msg/MeshFile")(filename="", data=np.zeros(0, np.uint8)),
        mesh_use_embedded_materials=False)


def marker_array(markers: list[Any]) -> bytes:
    return serialize(msg("visualization_msgs/msg/MarkerArray")(markers=markers))


def diagnostic_status(level: int, name: str, message: str, hardware_id: str, values: dict[str, Any]) -> Any:
    kv = msg("diagnostic_msgs/msg/KeyValue")
    return msg("diagnostic_msgs/msg/DiagnosticStatus")(
        level=int(level), name=name, message=message, hardware_id=hardware_id,
        values=[kv(key=str(k), value=str(v)) for k, v in values.items()])


def diagnostic_array(t_ns: int, statuses: list[Any]) -> bytes:
    return serialize(msg("diagnostic_msgs/msg/DiagnosticArray")(header=header(t_ns, ""), status=statuses))
