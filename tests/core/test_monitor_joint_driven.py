"""The monitor driven by the joint stream: a scene sensed without a base F/T sensor (motor currents,
joint torques, a flange F/T sensor) is judged at every joint sample, with the F/T reading at its time."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import ftc_hw.monitor as monitor_module
from ftc_hw.bus import Bus, JointFrame, WrenchFlag, WrenchFrame
from ftc_hw.detection import Detection
from ftc_hw.monitor import MONITOR_INPUT, LiveMonitor
from ftc_hw.pipeline import FrameResult
from ftc_hw.scene import JointTorqueSpec, load_scene


class RecordingPipeline:
    """Stands in for the joint-driven pipeline: keeps what the monitor hands it (the plumbing under test)."""

    in_contact = False

    def __init__(self, scene, settings=None):
        self.calls, self.tares = [], []

    def process_joints(self, t_ns, q, qd, *, current=None, tau_j=None, wrench=None, t_device_ns=None,
                       joint_gap_ns=0):
        self.calls.append(dict(t_ns=t_ns, q=q, current=current, tau_j=tau_j, wrench=wrench, gap=joint_gap_ns))
        det = Detection(active=False, d2=0.0, blind=False, probability=0.0, change=None, onset_t_ns=None)
        return FrameResult(t_ns, np.zeros(6), det, None, None, ())

    def tare(self, raw_mean, q, samples, t_ns, tau_j=None):
        self.tares.append((None if raw_mean is None else np.asarray(raw_mean).copy(), samples, tau_j))


@pytest.fixture
def recording(monkeypatch):
    monkeypatch.setattr(monitor_module, "pipeline_for", RecordingPipeline)


def _joints(t_ns, k, n=6, tau=None):
    q = np.full(n, 0.01 * k)
    return JointFrame.make(t_ns, q, np.zeros(n), np.full(n, 0.5), tau, source="arm", seq=k)


def _flange_scene():
    scene = load_scene("ur5e")
    flange = dataclasses.replace(scene.sensor, mount="flange", site="flange")
    return dataclasses.replace(scene, sensor=flange).with_sensing(["currents", "flange_ft"])


def test_currents_only_is_driven_by_the_joints_with_no_wrench_and_no_tare(recording):
    scene = load_scene("ur5e").with_sensing(["currents"])
    bus = Bus()
    inputs = bus.subscribe(MONITOR_INPUT, maxsize=100)
    monitor = LiveMonitor(bus, scene)
    assert monitor.driver == "joints" and monitor.tared and "sensor" not in monitor.lost_after_ns
    for k in range(5):
        monitor.handle(_joints(1_000_000 * (k + 1), k))
    calls = monitor.pipeline.calls
    assert len(calls) == 5 and all(c["wrench"] is None and c["tau_j"] is None for c in calls)
    np.testing.assert_array_equal(calls[-1]["current"], np.full(6, 0.5))
    recorded = inputs.drain()
    assert len(recorded) == 5 and recorded[0].wrench.shape == (0,)


def test_a_flange_sensor_is_sampled_at_each_joint_sample_after_its_tare(recording):
    scene = _flange_scene()
    monitor = LiveMonitor(Bus(), scene, tare_s=0.002)
    assert monitor.driver == "joints" and not monitor.tared
    for k in range(20):  # F/T at 2 kHz, a ramp in fx: 1 N per ms
        w = np.zeros(6)
        w[0] = 0.5 * k
        monitor.on_wrench(WrenchFrame.make(500_000 * k, w, source="ft", seq=k,
                                           flags=WrenchFlag.SATURATED if k == 15 else 0))
    for k in range(1, 9):  # joints at 1 kHz
        monitor.handle(_joints(1_000_000 * k, k))
    assert monitor.tared and len(monitor.pipeline.tares) == 1  # the first 2 ms went to the tare
    calls = monitor.pipeline.calls
    assert [c["t_ns"] for c in calls] == [1_000_000 * k for k in range(4, 9)]  # 1-3 ms: the tare
    for c in calls:
        assert c["wrench"][0] == pytest.approx(c["t_ns"] / 1e6, abs=1e-9)  # interpolated at the joint time


def test_joint_torques_come_from_the_joint_frame_and_a_frame_without_them_is_counted(recording):
    scene = dataclasses.replace(load_scene("ur5e"), joint_torque=JointTorqueSpec(
        noise_std=np.full(6, 0.05), range=np.full(6, 100.0), offset=np.zeros(6))).with_sensing(["joint_torques"])
    monitor = LiveMonitor(Bus(), scene, tare_s=None)
    monitor.handle(_joints(1_000_000, 1, tau=np.arange(6.0)))
    monitor.handle(_joints(2_000_000, 2))  # no tau: not judged, counted
    assert len(monitor.pipeline.calls) == 1
    np.testing.assert_array_equal(monitor.pipeline.calls[0]["tau_j"], np.arange(6.0))
    assert monitor.pipeline.calls[0]["current"] is None
    assert monitor.counters["no_joint_torques"] == 1


def test_missed_joint_samples_are_a_gap(recording):
    monitor = LiveMonitor(Bus(), load_scene("ur5e").with_sensing(["currents"]))
    t = 0
    for k in range(140):  # the stream's period is known after 128 samples
        t += 2_000_000
        monitor.handle(_joints(t, k))
    monitor.handle(_joints(t + 10_000_000, 140))  # four samples missed
    assert monitor.pipeline.calls[-1]["gap"] == 10_000_000
    assert monitor.pipeline.calls[-2]["gap"] == 0
    assert monitor.counters["joint_gap_frames"] == 1


def test_joint_torque_sensors_are_tared_at_rest_without_a_calibration(recording):
    scene = dataclasses.replace(load_scene("ur5e"), joint_torque=JointTorqueSpec(
        noise_std=np.full(6, 0.05), range=np.full(6, 100.0), offset=np.zeros(6))).with_sensing(["joint_torques"])
    monitor = LiveMonitor(Bus(), scene, tare_s=0.002)
    assert not monitor.tared
    for k in range(1, 6):
        monitor.handle(_joints(1_000_000 * k, k, tau=np.full(6, float(k))))
    (raw, samples, tau_j), = monitor.pipeline.tares  # the first 3 ms: the offsets' tare, no F/T in it
    assert raw is None and samples == 3 and tau_j == pytest.approx(np.full(6, 2.0))
    assert len(monitor.pipeline.calls) == 2
