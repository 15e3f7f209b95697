"""What the vendors' ROS 2 drivers publish, as data: topic, joint names, what ``effort`` is, the wrench's
frame (docs/ros.md, "Inputs from ROS topics", gives each one's source). ``ftc ros publish`` publishes a
scene's devices the same way; a rig file reading those drivers says the same (the ros-* kinds' params).

- ``ur_robot_driver`` (Universal_Robots_ROS2_Driver): ros2_control's ``joint_state_broadcaster`` on
  ``/joint_states``, UR's joint names, ``effort`` = RTDE ``actual_current`` (A); the flange wrench from
  ``force_torque_sensor_broadcaster`` on ``/force_torque_sensor_broadcaster/wrench`` in
  ``tool0_controller``.
- ``franka_ros2``: the ``joint_state_broadcaster`` remapped to ``/franka/joint_states``, joints
  ``fr3_joint1..7`` (an FR3; ``panda_joint1..7`` on a Panda), ``effort`` = libfranka's ``tau_J`` (N m).
- ``ur_robot_driver``'s ``dashboard_client`` node serves ``/dashboard_client/stop`` (std_srvs/Trigger: the
  dashboard server's ``stop``, which stops the running program and the arm with it).
- ``net_ft_driver`` (ros2_net_ft_driver): ``force_torque_sensor_broadcaster``'s
  ``/force_torque_sensor_broadcaster/wrench`` in its configured ``frame_id``.
All publish with rclcpp's ``SystemDefaultsQoS`` (reliable, volatile, keep last).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from ftc_hw.scene import DeviceSpec, Scene

JOINT_STATES = "/joint_states"
FRANKA_JOINT_STATES = "/franka/joint_states"
FT_BROADCASTER_WRENCH = "/force_torque_sensor_broadcaster/wrench"
UR_FLANGE_FRAME = "tool0_controller"
FRANKA_PREFIX = {"pylibfranka": "fr3_", "panda-py": "panda_"}  # the device's client: its arm's robot_type
UR_DASHBOARD_STOP = "/dashboard_client/stop"  # ur_robot_driver's dashboard client: std_srvs/Trigger


def stop_service(arm: DeviceSpec, asked: str | None = None) -> str:
    """The arm's driver's stop service (``asked``: the user's; "" none): ur_robot_driver's dashboard
    ``stop`` for a UR; franka_ros2 offers none that takes a std_srvs/Trigger."""
    if asked is not None:
        return asked
    return UR_DASHBOARD_STOP if arm.kind == "ur-rtde" else ""


@dataclass(frozen=True)
class Stream:
    """One device stream on one ROS topic. ``source``: the bus's device name; ``names``: the JointState's
    joint names in the scene's order; ``effort``: current (A) or torque (N m); ``frame_id``: the wrench's."""

    source: str
    kind: Literal["joints", "wrench"]
    topic: str
    names: tuple[str, ...] = ()
    effort: str = "current"
    frame_id: str = ""


def joint_stream(scene: Scene, arm: DeviceSpec, *, topic: str | None = None, prefix: str | None = None) -> Stream:
    """The arm's JointState as its vendor's driver publishes it."""
    franka = arm.kind == "franka"
    if prefix is None:
        prefix = FRANKA_PREFIX.get(str(arm.params.get("client", "pylibfranka")), "") if franka else ""
    effort = "torque" if scene.joint_torque is not None else "current"
    return Stream(arm.name, "joints", topic or (FRANKA_JOINT_STATES if franka else JOINT_STATES),
                  tuple(prefix + j for j in scene.robot.joints), effort=effort)


def wrench_stream(scene: Scene, ft: DeviceSpec, *, topic: str | None = None, frame_id: str | None = None) -> Stream:
    """The F/T sensor's WrenchStamped as ros2_controllers' force_torque_sensor_broadcaster publishes it (the UR
    and Net F/T drivers both use it): in the UR flange's frame for a UR's own sensor, else the scene's sensor
    frame."""
    sensor = scene.require_ft("publishing a wrench")
    default_frame = UR_FLANGE_FRAME if ft.kind == "ur-rtde" else sensor.site
    return Stream(ft.name, "wrench", topic or FT_BROADCASTER_WRENCH, frame_id=frame_id or default_frame)
