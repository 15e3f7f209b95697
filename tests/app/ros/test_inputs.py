"""The ROS input kinds (ftc_hw.app.ros.inputs) as a rig file makes them: their params checked as every
kind's, their adapters from the registry, and each received message to a frame on the bus, flagged,
or refused with a counter and one event (messages handed in directly: no ROS graph, no waiting)."""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import pytest
from geometry_msgs.msg import WrenchStamped
from sensor_msgs.msg import JointState

from ftc_hw.app.ros import RosUnavailable, context
from ftc_hw.app.ros.stop_service import StopClient, StopServer
from ftc_hw.bus import EVENTS_DEVICE, Bus, JointFlag, WrenchFlag
from ftc_hw.devices import registry
from ftc_hw.devices.base import DeviceError, DeviceIOError
from ftc_hw.devices.registry import make_adapter, roles_of
from ftc_hw.scene import SceneError, load_rig_scene, load_scene

from .conftest import UR_RIG

pytestmark = pytest.mark.compute

T0 = 1_700_000_000_000_000_000


def rig_scene(tmp_path: Path, text: str = UR_RIG, scene: str = "ur5e"):
    (tmp_path / "ros.toml").write_text(text)
    return load_rig_scene(scene, rig=tmp_path / "ros.toml")


def adapters(tmp_path: Path, text: str = UR_RIG, scene: str = "ur5e"):
    s = rig_scene(tmp_path, text, scene)
    bus = Bus()
    return bus, {d.name: make_adapter(d, bus, scene=s) for d in s.devices}


def joint_state(names, q, stamp_ns, effort=None):
    msg = JointState(name=list(names), position=list(q), velocity=[0.0] * len(names),
                     effort=list(effort) if effort is not None else [1.0] * len(names))
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 10**9)
    return msg


def wrench(stamp_ns, frame_id="ft_sensor", fz=-202.0):
    msg = WrenchStamped()
    msg.header.frame_id = frame_id
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 10**9)
    msg.wrench.force.z = fz
    return msg


def events(bus: Bus) -> list[str]:
    return [e.message for e in bus.history(EVENTS_DEVICE)]


def test_a_rig_file_turns_a_scene_s_devices_into_ros_inputs(tmp_path):
    scene = rig_scene(tmp_path)
    ft, arm = scene.devices
    assert (ft.kind, ft.transport, ft.params) == ("ros-wrench", "ros", {
        "topic": "/force_torque_sensor_broadcaster/wrench", "rate_hz": 1000.0})
    assert arm.kind == "ros-joint-state" and "frequency" not in arm.params  # the UR's params are gone
    assert roles_of(ft, scene) == {"ft"} and roles_of(arm, scene) == {"arm"}
    with pytest.raises(SceneError, match="arm.effort.*one of current, torque, none"):
        rig_scene(tmp_path, UR_RIG + 'effort = "amps"\n')
    with pytest.raises(SceneError, match="arm.topic.*required by device kind ros-joint-state"):
        rig_scene(tmp_path, '[arm]\nkind = "ros-joint-state"\n')
    with pytest.raises(SceneError, match="ft.reliability.*one of reliable, best_effort"):
        rig_scene(tmp_path, UR_RIG.replace("rate_hz = 1000.0", 'reliability = "sometimes"'))
    with pytest.raises(SceneError, match="kind changes in a rig file"):
        load_rig_scene("ur5e", ["arm.kind=ros-joint-state"])


def test_joints_are_mapped_by_name_and_effort_is_the_current(tmp_path):
    bus, devs = adapters(tmp_path)
    arm = devs["arm"]
    scene = load_scene("ur5e")
    names = list(reversed(scene.robot.joints))
    frame = arm.handle(joint_state(names, [5.0, 4.0, 3.0, 2.0, 1.0, 0.0], T0, effort=[2.0] * 6), 123)
    np.testing.assert_array_equal(frame.q, [0.0, 1.0, 2.0, 3.0, 4.0, 5.0])
    np.testing.assert_array_equal(frame.current, [2.0] * 6)
    np.testing.assert_allclose(frame.tau, 2.0 * scene.robot.torque_constant)  # UR: torque = kt x current
    assert (frame.t_host_ns, frame.t_device_ns, frame.flags) == (123, T0, JointFlag.NONE)
    assert bus.latest("joints/arm") is frame


def test_franka_s_measured_torques_under_its_prefixed_names(tmp_path):
    bus, devs = adapters(tmp_path, '[arm]\nkind = "ros-joint-state"\ntopic = "/franka/joint_states"\n'
                         'joint_prefix = "fr3_"\n', scene="fr3")
    arm = devs["arm"]
    assert arm.effort == "torque"  # the scene has joint torque sensors
    names = [f"fr3_joint{i}" for i in range(1, 8)]
    frame = arm.handle(joint_state(names, np.arange(7.0), T0, effort=np.arange(7.0) + 0.5), 1)
    np.testing.assert_array_equal(frame.tau, np.arange(7.0) + 0.5)
    np.testing.assert_array_equal(frame.current, np.zeros(7))
    # the same message under the scene's bare names is not the scene's: refused, counted, said once
    for _ in range(3):
        assert arm.handle(joint_state([n[4:] for n in names], np.arange(7.0), T0 + 10**6), 2) is None
    assert arm.counters["joint_names"] == 3 and arm.counters["frames"] == 1
    said = [m for m in events(bus) if "no joint fr3_joint1" in m]
    assert len(said) == 1 and "joint_names counts them" in said[0]


def test_nan_wrong_lengths_and_backward_stamps(tmp_path):
    bus, devs = adapters(tmp_path)
    arm = devs["arm"]
    names = load_scene("ur5e").robot.joints
    period = 2_000_000
    assert arm.handle(joint_state(names, [0.0] * 6, T0), 1) is not None
    nan = joint_state(names, [0.0] * 6, T0 + period, effort=[1.0, float("nan"), 1, 1, 1, 1])
    assert arm.handle(nan, 2) is None and arm.counters["bad_values"] == 1
    short = joint_state(names, [0.0] * 6, T0 + period)
    short.velocity = [0.0] * 5
    assert arm.handle(short, 3) is None and arm.counters["bad_messages"] == 1
    # a message lost (judged from the stamps at 500 Hz): the next frame flagged, the loss counted
    gap = arm.handle(joint_state(names, [0.0] * 6, T0 + 3 * period), 4)
    assert gap.flags & JointFlag.SEQ_GAP and gap.seq == 3 and arm.counters["missed_packets"] == 2
    assert arm.handle(joint_state(names, [0.0] * 6, T0 + 3 * period), 5) is None  # the same stamp again
    assert arm.counters["duplicates"] == 1
    back = arm.handle(joint_state(names, [0.0] * 6, T0), 6)
    assert back.flags & JointFlag.CLOCK_SUSPECT and back.seq == 4 and arm.counters["stamp_backwards"] == 1
    assert any("NaN or Inf in effort" in m for m in events(bus))


def test_a_wrench_in_another_frame_is_an_error_not_a_frame(tmp_path):
    bus, devs = adapters(tmp_path)
    ft = devs["ft"]
    assert ft.frame_id == "ft_sensor"  # the scene's sensor site
    assert ft.handle(wrench(T0, frame_id="tool0"), 1) is None
    assert ft.counters["wrong_frame"] == 1 and bus.latest("wrench/ft") is None
    assert any("wrench in frame 'tool0', not the scene's sensor frame 'ft_sensor'" in m for m in events(bus))
    ok = ft.handle(wrench(T0), 2)
    assert ok.wrench[2] == -202.0 and ok.t_device_ns == T0
    # a reading at the sensor's range (the scene's Omega160: Fz 3750 N) is a lower bound
    assert ft.handle(wrench(T0 + 10**6, fz=-3750.0), 3).flags & WrenchFlag.SATURATED
    gap = ft.handle(wrench(T0 + 5 * 10**6), 4)
    assert gap.flags & WrenchFlag.SEQ_GAP and ft.counters["lost"] == 3
    assert ft.handle(wrench(T0 + 6 * 10**6, fz=float("inf")), 5) is None and ft.counters["bad_values"] == 1
    _, named = adapters(tmp_path, UR_RIG.replace('rate_hz = 1000.0', 'frame_id = "netft_link"'))
    assert named["ft"].frame_id == "netft_link"


def test_without_the_extra_a_ros_kind_says_what_to_install(tmp_path, monkeypatch):
    scene = rig_scene(tmp_path)
    monkeypatch.setattr("ftc_hw.app.ros.availability.missing_modules", lambda: ["rclpy"])
    monkeypatch.delitem(sys.modules, "ftc_hw.app.ros.inputs")
    monkeypatch.setattr(registry, "_registered", {})
    with pytest.raises(RosUnavailable, match=r"pip install 'ftc-hw\[ros\]'"):
        make_adapter(scene.devices[1], Bus(), scene=scene)


def test_the_stop_reflex_on_a_ros_arm_needs_its_drivers_stop_service(tmp_path):
    bus, made = adapters(tmp_path)
    with pytest.raises(DeviceError, match="params.stop_service .*/dashboard_client/stop"):
        made["arm"].stop()
    bus, made = adapters(tmp_path, UR_RIG + 'stop_service = "/ftc_test/no_server"\n')
    try:
        with pytest.raises(DeviceIOError, match="no server of /ftc_test/no_server"):
            made["arm"].stop()
        assert made["arm"].counters["stop_failures"] == 1
    finally:
        made["arm"].close()


def test_a_stop_service_call_is_answered_and_a_failing_stop_says_why():
    node = context.acquire("ftc_test")
    stops: list[int] = []

    def stop() -> None:
        stops.append(1)
        if len(stops) == 2:
            raise RuntimeError("not in remote control")

    server = StopServer(node, "/ftc_test/stop", stop)
    client = StopClient(node, "/ftc_test/stop", timeout_s=5.0)
    try:
        deadline = time.monotonic() + 10.0
        while not client.ready() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert client.call() == "Stopped"
        with pytest.raises(DeviceError, match="refused the stop: RuntimeError: not in remote control"):
            client.call()
        assert (server.calls, server.failures, len(stops)) == (2, 1, 2)
    finally:
        client.close()
        server.close()
        context.release()
