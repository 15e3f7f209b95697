"""The UR adapter's flange F/T stream from one RTDE packet's values, computed (a stand-in for ur_rtde's
receive interface: no process, no clock): the WrenchFrame beside the JointFrame, its flags, bad values.
Against the emulator through ur_rtde: test_ur_adapter.py."""
from __future__ import annotations

import pytest

from ftc_hw.bus import Bus, JointFlag, WrenchFlag
from ftc_hw.devices.registry import make_adapter
from ftc_hw.devices.ur import URArm
from ftc_hw.scene import load_scene

pytestmark = pytest.mark.compute  # computes only (nothing timed): runs with the others on every core

RANGE = [100.0, 100.0, 100.0, 10.0, 10.0, 10.0]


class Packet:
    """What ur_rtde's getters return for the newest packet."""

    def __init__(self, ts: float, wrench) -> None:
        self.ts, self.wrench = ts, list(wrench)

    def getTimestamp(self) -> float:  # noqa: N802 - ur_rtde's names
        return self.ts

    def getActualQ(self) -> list[float]:  # noqa: N802
        return [0.1] * 6

    def getActualQd(self) -> list[float]:  # noqa: N802
        return [0.0] * 6

    def getActualCurrent(self) -> list[float]:  # noqa: N802
        return [0.5] * 6

    def getFtRawWrench(self) -> list[float]:  # noqa: N802
        return self.wrench

    def getRobotMode(self) -> int:  # noqa: N802
        return 7

    def getSafetyMode(self) -> int:  # noqa: N802
        return 1

    def getRuntimeState(self) -> int:  # noqa: N802
        return 2


def _arm(ft: bool = True) -> tuple[URArm, Bus]:
    bus = Bus()
    return URArm("arm", bus, "192.0.2.10", ft=ft, ft_range=RANGE if ft else None), bus


def test_each_packet_is_a_joint_frame_and_a_wrench_frame_of_the_same_times():
    arm, bus = _arm()
    wrenches, joints = bus.subscribe("wrench/arm"), bus.subscribe("joints/arm")
    w = [1.5, -2.0, 30.0, 0.25, -0.5, 0.125]
    arm._publish(Packet(10.002, w), 10.002)
    arm._publish(Packet(10.008, w), 10.008)  # two packets lost in between
    (j1, j2), (f1, f2) = joints.drain(), wrenches.drain()
    assert list(f1.wrench) == w and f1.source == "arm" and f1.flags == WrenchFlag.NONE
    for j, f in ((j1, f1), (j2, f2)):
        assert (f.t_host_ns, f.t_device_ns, f.seq) == (j.t_host_ns, j.t_device_ns, j.seq)
    assert f2.seq == 5004 and j2.flags & JointFlag.SEQ_GAP and f2.flags == WrenchFlag.SEQ_GAP
    assert arm.counters["ft_frames"] == 2 and arm.roles == {"arm", "ft"}


def test_a_reading_at_the_sensor_range_is_flagged_saturated_and_a_bad_one_is_counted():
    arm, bus = _arm()
    wrenches, joints = bus.subscribe("wrench/arm"), bus.subscribe("joints/arm")
    arm._publish(Packet(1.000, [0.0, 0.0, -100.0, 0.0, 0.0, 0.0]), 1.000)  # Fz at -100 N: clipped there
    arm._publish(Packet(1.002, [0.0, 0.0, 99.9, 9.99, 0.0, 0.0]), 1.002)
    arm._publish(Packet(1.004, [0.0, float("nan"), 0.0, 0.0, 0.0, 0.0]), 1.004)
    arm._publish(Packet(1.006, [0.0, 0.0, 0.0, 0.0]), 1.006)  # not six values
    flags = [f.flags for f in wrenches.drain()]
    assert flags == [WrenchFlag.SATURATED, WrenchFlag.NONE]
    assert len(joints.drain()) == 4  # the joint state is published whatever the sensor said
    assert arm.counters["saturated"] == 1 and arm.counters["ft_bad"] == 2


def test_without_the_sensor_nothing_is_asked_or_published():
    arm, bus = _arm(ft=False)
    wrenches = bus.subscribe("wrench/arm")
    arm._publish(Packet(1.0, [float("nan")] * 6), 1.0)
    assert not wrenches.drain() and "ft_raw_wrench" not in arm.variables
    assert arm.roles == {"arm"} and arm.topics == ("joints/arm",)


def test_a_base_sensor_s_range_is_not_the_flange_sensor_s():
    scene = load_scene("ur5e")  # its sensor is under the base: an arm told to read its flange sensor
    arm = make_adapter(scene.devices[1], Bus(), "192.0.2.10", scene=scene, ft=True)
    assert arm.ft and arm.ft_range is None  # no range to judge saturation by: none flagged
