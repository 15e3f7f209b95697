"""The UR emulator's flange F/T sensor, computed (no process, no clock): the wrench the controller reports
from a flange sensor's reading, the sample each packet takes from the F/T ring, and the scenes refused.
Through ur_rtde and the adapter: tests/devices/test_ur_adapter.py."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ftc_hw.scene import load_scene
from ftc_hw.sim_devices import ur_data as D
from ftc_hw.sim_devices.link import FT_WIDTH, JointRecord, Ring, RingReader
from ftc_hw.sim_devices.ur import Controller, OutputRecipe, Tick, UREmulator
from ftc_hw.sim_devices.ur_ft import FlangeSamples
from ftc_hw.sim_devices.ur_model import URKinematics, flange_wrench_base
from tests.ur_flange import flange_scene

pytestmark = pytest.mark.compute  # computes only (nothing timed): runs with the others on every core

BASE = load_scene("ur5e")


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    return flange_scene(tmp_path_factory.mktemp("ur-flange"))


def _rotation(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])


@pytest.mark.parametrize("reports", ["arm_on_base", "base_on_arm"])
def test_a_push_on_the_tool_is_the_same_base_wrench_whichever_way_the_sensor_reports(reports):
    """A push p (sensor frame) with moment c x p about the sensor: ``arm_on_base`` reads (+p, +c x p),
    ``base_on_arm`` the negative (docs/conventions.md); both are the external wrench R (p, c x p)."""
    p, c = np.array([3.0, -20.0, 7.5]), np.array([0.01, 0.02, 0.15])
    push = np.concatenate([p, np.cross(c, p)])
    sign = 1.0 if reports == "base_on_arm" else -1.0
    rot = _rotation(0.7)
    got = flange_wrench_base(-sign * push, sign, rot)
    assert got == pytest.approx(np.concatenate([rot @ p, rot @ np.cross(c, p)]), abs=1e-12)
    assert np.linalg.norm(got[:3]) == pytest.approx(np.linalg.norm(p))


def _tick(scene, kin, q, ft):
    z = np.zeros(6)
    ctl = Controller((5, 9, 0, 0), None, "arm", "1", "UR5e")
    return Tick(JointRecord(0.004, q, z, z, z, z, z), ctl, kin, np.full(6, 25.0), 0.0, ft, scene.sensor.reading_sign)


def test_packets_carry_the_flange_reading_and_the_wrench_it_implies_in_base_axes(scene):
    kin = URKinematics(scene)
    q = np.asarray(scene.robot.home) + np.array([0.3, -0.2, 0.1, 0.4, -0.5, 0.6])
    reading = np.array([4.0, -2.0, 30.0, 0.5, -0.25, 0.1])  # arm_on_base: the push itself (sensor frame)
    tick = _tick(scene, kin, q, reading)
    recipe = OutputRecipe(1, ["timestamp", "ft_raw_wrench", "actual_TCP_force", "tcp_force_scalar"], 500.0)
    values = recipe.struct.unpack(recipe.pack(tick))
    rot = kin.tcp_rotation()  # base_R_flange at q: the sensor's axes (its site is the flange's)
    assert values[0] == 1 and values[1] == 0.004
    assert np.array_equal(values[2:8], reading)  # ft_raw_wrench: the reading, flange frame, as it is
    assert values[8:14] == pytest.approx(np.concatenate([rot @ reading[:3], rot @ reading[3:]]), abs=1e-12)
    assert values[14] == pytest.approx(np.linalg.norm(reading[:3]))
    assert not np.allclose(rot, np.eye(3), atol=0.1)  # the rotation mattered


def test_without_a_flange_sensor_both_are_the_current_based_estimate():
    kin = URKinematics(BASE)
    q = np.asarray(BASE.robot.home, dtype=float)
    kin.update(q, np.zeros(6), np.zeros(6))
    tau = kin.d.qfrc_inverse[kin.dadr] - kin.jacobian.T @ np.array([0.0, 0.0, -25.0, 0.0, 0.0, 0.0])
    z = np.zeros(6)
    tick = Tick(JointRecord(0.0, q, z, z, z, tau, z), Controller((5, 9, 0, 0), None, "arm", "1", "UR5e"), kin,
                np.full(6, 25.0), 0.0)
    assert tick.tcp_force == pytest.approx([0.0, 0.0, -25.0, 0.0, 0.0, 0.0], abs=0.05)  # damped least squares
    rot = kin.tcp_rotation()
    assert tick.ft_raw[:3] == pytest.approx(rot.T @ tick.tcp_force[:3])


def _ring(rate_hz: float = 500.0) -> tuple[Ring, FlangeSamples]:
    ring = Ring(FT_WIDTH, slots=64)
    return ring, FlangeSamples(RingReader(ring), rate_hz)


def test_each_packet_takes_the_newest_f_t_sample_at_or_before_its_time():
    ring, samples = _ring()
    try:
        assert np.array_equal(samples.at(0.002), np.zeros(6)) and samples.counts["ft_missing"] == 1
        for k in range(10):  # the world's samples fall between the 2 ms grid points
            ring.append_parts((k + 0.75) * 0.002, (np.full(6, float(k)), np.zeros(6)))
        assert samples.at(0.002 * 4)[0] == 3.0  # 7.5 ms: the newest at or before 8 ms
        assert samples.at(0.002 * 4 + 0.0015)[0] == 4.0  # exactly a sample's time: that one
        assert samples.at(0.001)[0] == 0.0 and samples.counts["ft_not_at_time"] == 1  # before all: the oldest
        assert samples.at(0.030)[0] == 9.0 and samples.counts["ft_late"] == 1  # 10.5 ms old: late
        assert samples.at(0.0205)[0] == 9.0 and samples.counts["ft_late"] == 1  # 1 ms old: on time
    finally:
        ring.close()


def test_a_flange_sensor_elsewhere_than_the_flange_frame_is_refused(scene):
    device = scene.devices[0]
    elsewhere = dataclasses.replace(scene, sensor=dataclasses.replace(scene.sensor, site="ft_sensor"))
    with pytest.raises(ValueError, match="not the tool flange frame"):
        UREmulator(device, elsewhere, None, {"address": "127.0.0.41"})
    nowhere = dataclasses.replace(scene, sensor=dataclasses.replace(scene.sensor, site="no_such_site"))
    with pytest.raises(ValueError, match="no site 'no_such_site'"):  # ArmModel's SceneError
        UREmulator(device, nowhere, None, {"address": "127.0.0.41"})
    for version in ("3.15", "5.8"):  # a CB3 has no flange sensor; RTDE has ft_raw_wrench from 5.9
        with pytest.raises(ValueError, match="from 5.9"):
            UREmulator(device, scene, None, {"address": "127.0.0.41", "controller_version": version,
                                             "frequency": 125.0})
    assert D.OUTPUTS["ft_raw_wrench"] == "VECTOR6D"
