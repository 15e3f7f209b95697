"""What ftc publishes on ROS 2 and writes to a ROS 2 bag: each topic's name, message type and QoS, as data
(docs/ros.md, "Outputs" and "Bags out", say why each is so). No ROS import here: the monitor's options and
the docs read it without the extra."""
from __future__ import annotations

from dataclasses import dataclass

DEFAULT_NAMESPACE = "/ftc"
CONTACT_FRAME = "ftc_contact"  # the newest contact's frame: origin at its point, axes the base frame's


@dataclass(frozen=True)
class Topic:
    """One topic: ``name`` relative to the namespace (absolute when it starts with ``/``: a ROS convention's
    own name), ``msgtype`` as ROS 2 names it, QoS (always reliable: a best-effort subscriber, RViz's default
    for sensor data, still matches a reliable publisher; the other way round does not), where it goes."""

    name: str
    msgtype: str
    depth: int
    latched: bool = False  # transient_local: a subscriber that joins late gets the last ``depth``
    live: bool = True  # published by ``ftc monitor --ros``
    bag: bool = True  # written by ``--record-format ros2``

    def full_name(self, namespace: str) -> str:
        if self.name.startswith("/"):
            return self.name
        return f"{namespace.rstrip('/')}/{self.name}" if namespace.strip("/") else f"/{self.name}"


WRENCH_STAMPED = "geometry_msgs/msg/WrenchStamped"
EXTERNAL_WRENCH = Topic("external_wrench", WRENCH_STAMPED, depth=5000)  # docs/ros.md: the repair of a lost sample
CONTACT_WRENCH = Topic("contact_wrench", WRENCH_STAMPED, depth=1, latched=True)
CONTACT_POSE = Topic("contact_pose", "geometry_msgs/msg/PoseStamped", depth=1, latched=True)
MARKERS = Topic("contact_markers", "visualization_msgs/msg/MarkerArray", depth=1, latched=True)
EVENTS = Topic("events", "std_msgs/msg/String", depth=100, latched=True)
DIAGNOSTICS = Topic("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", depth=10)
# bags only: rclpy has no tf2_msgs (not on the package index), the inputs are the drivers' to publish (their
# names here are ur_robot_driver's and ros2_net_ft_driver's; a bag takes the scene's drivers' defaults:
# ftc_hw.app.ros.topic_map.default_map)
TF = Topic("/tf", "tf2_msgs/msg/TFMessage", depth=100, live=False)
JOINT_STATES = Topic("/joint_states", "sensor_msgs/msg/JointState", depth=1000, live=False)
FT_WRENCH = Topic("/force_torque_sensor_broadcaster/wrench", WRENCH_STAMPED, depth=1000, live=False)
RAW_WRENCH = Topic("raw_wrench", WRENCH_STAMPED, depth=1000, live=False)  # a flange sensor's: no driver's default

TOPICS = (EXTERNAL_WRENCH, CONTACT_WRENCH, CONTACT_POSE, MARKERS, EVENTS, DIAGNOSTICS, TF, JOINT_STATES, FT_WRENCH,
          RAW_WRENCH)


def check_namespace(namespace: str) -> str:
    """``namespace`` as a ROS namespace (``/ftc``), or ValueError saying what a ROS name allows."""
    ns = "/" + namespace.strip("/")
    parts = [p for p in ns.split("/") if p]
    for p in parts:
        if not (p[0].isalpha() or p[0] == "_") or not all(c.isalnum() or c == "_" for c in p):
            raise ValueError(f"ROS namespace {namespace!r}: each part must start with a letter or _ and hold only "
                             "letters, digits and _")
    return ns
