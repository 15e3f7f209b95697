"""Which topics of a ROS 2 bag are the scene's arm and F/T sensor (``ftc replay BAG``, ``ftc identify BAG``,
``--topics map.toml``; docs/ros.md, "Bags in"). Pure: no ROS import.

A map file::

    [joint_states]
    topic = "/joint_states"
    effort = "current"            # current (A, UR's ur_robot_driver) | torque (N m, franka_ros2) | none
    [joint_states.names]          # the driver's joint name = the scene's (default: the same names)
    fr3_joint1 = "joint1"
    [wrench]                      # optional: a geometry_msgs/WrenchStamped of the scene's F/T sensor
    topic = "/force_torque_sensor_broadcaster/wrench"
    frame_id = "tool0"            # what its header.frame_id must say: the scene's sensor frame

Without a file, the defaults of the driver the scene's arm is read with (:func:`default_map`).
"""
from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path

from ftc_hw.devices.registry import role_of
from ftc_hw.scene import Scene

EFFORTS = ("current", "torque", "none")
# the scene sensing kind each effort gives
SENSING_OF_EFFORT = {"current": "currents", "torque": "joint_torques"}

# ur_robot_driver (Universal_Robots_ROS2_Driver): joint_state_broadcaster on /joint_states; its hardware
# interface fills effort from RTDE's actual_current (A) (ur_robot_driver/src/hardware_interface.cpp, read()).
UR_JOINT_STATES = "/joint_states"
# franka_ros2 (franka_bringup/launch/franka.launch.py): ros2_control_node's joint_states remapped to
# franka/joint_states; effort is libfranka's tau_J, the measured link-side torque (franka_hardware,
# read()); joint names <arm_id>_joint1..7 (fr3_joint1, panda_joint1).
FRANKA_JOINT_STATES = "/franka/joint_states"
# ros2_net_ft_driver (net_ft_driver/config/net_ft_broadcaster.yaml): ros2_controllers'
# force_torque_sensor_broadcaster publishes on ~/wrench, frame_id tool0 as configured there.
NETFT_WRENCH = "/force_torque_sensor_broadcaster/wrench"
NETFT_FRAME = "tool0"


class TopicMapError(ValueError):
    """A topic map that cannot be used (the message names the file and the key)."""


@dataclass(frozen=True)
class JointStatesTopic:
    """``sensor_msgs/JointState`` on ``topic``; ``effort``: what its effort field holds; ``names``: (the
    driver's joint name, the scene's joint name) for each of the scene's joints."""

    topic: str
    effort: str
    names: tuple[tuple[str, str], ...]

    def bag_names(self, scene_joints: tuple[str, ...] | list[str]) -> list[str]:
        """The driver's name of each scene joint, in the scene's order."""
        back = {scene: bag for bag, scene in self.names}
        return [back[j] for j in scene_joints]


@dataclass(frozen=True)
class WrenchTopic:
    """``geometry_msgs/WrenchStamped`` on ``topic``, read only where ``header.frame_id == frame_id``."""

    topic: str
    frame_id: str


@dataclass(frozen=True)
class TopicMap:
    joint_states: JointStatesTopic
    wrench: WrenchTopic | None
    source: str  # the file, or whose defaults

    @property
    def sensing(self) -> frozenset[str]:
        """The scene sensing kinds the mapped topics can give (``flange_ft``/``base_ft`` by the scene's mount)."""
        kinds = {SENSING_OF_EFFORT[self.joint_states.effort]} if self.joint_states.effort != "none" else set()
        return frozenset(kinds | ({"ft"} if self.wrench is not None else set()))


def _arm_kind(scene: Scene) -> str | None:
    return next((d.kind for d in scene.devices if role_of(d.kind) == "arm"), None)


def default_map(scene: Scene) -> TopicMap:
    """The drivers' defaults for the scene's arm (and a base F/T sensor read by a Net F/T box)."""
    joints = list(scene.robot.joints)
    kind = _arm_kind(scene)
    if kind == "franka":
        arm_id = "panda" if scene.name.startswith("panda") else "fr3"
        names = tuple((f"{arm_id}_{j}", j) for j in joints)
        js = JointStatesTopic(FRANKA_JOINT_STATES, "torque", names)
        source = f"franka_ros2's defaults ({arm_id})"
    else:
        effort = "current" if scene.has_currents else "torque" if scene.joint_torque is not None else "none"
        js = JointStatesTopic(UR_JOINT_STATES, effort, tuple((j, j) for j in joints))
        source = "ur_robot_driver's defaults" if kind == "ur-rtde" else "joint_state_broadcaster's defaults"
    # UR's own wrench topic is not a default: it carries actual_TCP_force (the controller's payload-
    # compensated estimate at the TCP), not the raw flange reading the scene's flange sensor models.
    mount = scene.sensor.mount if scene.sensor is not None else None
    wrench = WrenchTopic(NETFT_WRENCH, NETFT_FRAME) if mount == "base" else None
    return TopicMap(js, wrench, source + (" with ros2_net_ft_driver's wrench" if wrench else ""))


def _str(table: dict, key: str, where: str, default: str | None = None) -> str:
    value = table.get(key, default)
    if not isinstance(value, str) or not value:
        raise TopicMapError(f"{where}: {key!r} must be a non-empty string")
    return value


def load_topic_map(path: Path | str, scene: Scene) -> TopicMap:
    """The map in the TOML file at ``path``, checked against ``scene``'s joints; the defaults fill what it
    leaves out (a file with only ``[wrench]`` keeps the driver's joint states)."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise TopicMapError(f"{path}: cannot read: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise TopicMapError(f"{path}: not TOML: {exc}") from None
    unknown = sorted(set(data) - {"joint_states", "wrench"})
    if unknown:
        raise TopicMapError(f"{path}: unknown table {unknown[0]!r} (known: joint_states, wrench)")
    base = default_map(scene)
    js = _joint_states(data.get("joint_states", {}), base.joint_states, scene, f"{path} [joint_states]")
    wrench = base.wrench
    if "wrench" in data:
        table = data["wrench"]
        where = f"{path} [wrench]"
        wrench = WrenchTopic(_str(table, "topic", where), _str(table, "frame_id", where))
        if scene.sensor is None:
            raise TopicMapError(f"{where}: scene {scene.name!r} has no F/T sensor to map a wrench to")
    return TopicMap(js, wrench, str(path))


def _joint_states(table: dict, base: JointStatesTopic, scene: Scene, where: str) -> JointStatesTopic:
    effort = table.get("effort", base.effort)
    if effort not in EFFORTS:
        raise TopicMapError(f"{where}: effort {effort!r}: one of {', '.join(EFFORTS)}")
    names = table.get("names")
    if names is None:
        pairs = base.names
    else:
        if not isinstance(names, dict) or not all(isinstance(v, str) for v in names.values()):
            raise TopicMapError(f"{where}: names must map the driver's joint names to the scene's")
        pairs = tuple(names.items())
    scene_joints = list(scene.robot.joints)
    mapped = [s for _, s in pairs]
    stray = sorted(set(mapped) - set(scene_joints))
    missing = [j for j in scene_joints if j not in mapped]
    if stray or missing or len(mapped) != len(set(mapped)):
        raise TopicMapError(f"{where}: names must name each of scene {scene.name!r}'s joints once "
                            f"({', '.join(scene_joints)})" + (f"; not the scene's: {', '.join(stray)}" if stray else "")
                            + (f"; missing: {', '.join(missing)}" if missing else ""))
    return JointStatesTopic(_str(table, "topic", where, base.topic), effort, pairs)
