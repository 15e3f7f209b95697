"""ur_rtde's receive, IO and dashboard clients (the real ones) against the UR emulator, each in its own
process, the world in a third. Every emulator of this module binds 127.0.0.41 (ur_rtde hard-codes port
30004): other modules use other loopback addresses."""
from __future__ import annotations

import socket
import struct
import time

import dashboard_client
import numpy as np
import pytest
import rtde_io
import rtde_receive

from ftc_hw.model import ArmModel
from ftc_hw.scene import load_scene
from ftc_hw.sim_devices import ur_data as D
from ftc_hw.sim_devices.dynamixel import DynamixelEmulator
from ftc_hw.sim_devices.emulator import Emulator
from ftc_hw.sim_devices.host import WorldHost
from ftc_hw.sim_devices.link import JointRecord
from ftc_hw.sim_devices.ur import UREmulator
from ftc_hw.sim_devices.ur_model import rotation_vector

pytestmark = pytest.mark.realtime  # against the wall clock: ./run-tests runs it alone, after the others

ADDRESS = "127.0.0.41"
SCENE = load_scene("ur5e")
DEVICE = next(d for d in SCENE.devices if d.kind == "ur-rtde")


@pytest.fixture(scope="module")
def world():
    with WorldHost(SCENE, "sweep", devices=["arm"], options={"arm": {"address": ADDRESS}}, noise=False) as w:
        yield w


@pytest.fixture(scope="module")
def receive(world):
    r = rtde_receive.RTDEReceiveInterface(ADDRESS)  # default arguments: 500 Hz, the 5.9 default recipe
    yield r
    r.disconnect()


def collect(r, seconds: float) -> tuple[list[float], list[list[float]]]:
    ts, qs, last = [], [], None
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        t = r.getTimestamp()
        if t != last:
            q = r.getActualQ()
            if r.getTimestamp() == t:
                ts.append(t)
                qs.append(q)
            last = t
        time.sleep(0.0002)
    return ts, qs


def test_default_receive_reads_the_world_joint_angles_exactly(world, receive):
    assert receive.isConnected()
    ring = world.joint_reader()
    ts, qs = collect(receive, 1.0)
    world_q = {j.t: j.q for j in (JointRecord.from_row(rec, SCENE.n_joints) for rec in ring.new())}
    assert len(ts) > 100
    matched = [np.max(np.abs(np.array(q) - world_q[t])) for t, q in zip(ts, qs, strict=True) if t in world_q]
    assert len(matched) >= 0.9 * len(ts)
    assert max(matched) <= 1e-9
    ticks = np.array(ts) / 0.002  # e-Series: one packet per 2 ms of controller time
    assert np.allclose(ticks, np.round(ticks), atol=1e-6)


def test_default_recipe_values(world, receive):
    r = receive
    assert (r.getRobotMode(), r.getSafetyMode(), r.getRuntimeState()) == (7, 1, 2)
    assert r.getRobotStatus() == 3 and r.getJointMode() == [253] * 6
    assert not r.isProtectiveStopped() and not r.isEmergencyStopped()
    assert all(20.0 < t < 60.0 for t in r.getJointTemperatures())
    assert r.getPayload() == 0.0 and r.getPayloadCog() == [0.0, 0.0, 0.0]
    assert r.getOutputIntRegister(12) == 0 and r.getOutputDoubleRegister(19) == 0.0
    assert r.getActualMainVoltage() == 48.0 and r.getSpeedScaling() == 1.0
    # the TCP pose is the flange site's, from the same joint angles
    for _ in range(3):
        t, q, pose = r.getTimestamp(), r.getActualQ(), r.getActualTCPPose()
        if r.getTimestamp() == t:
            break
    flange = ArmModel(SCENE).base_T_site(np.array(q), "flange")
    assert pose == pytest.approx(list(flange[:3, 3]) + list(rotation_vector(flange[:3, :3])), abs=1e-9)
    force, raw = np.array(r.getActualTCPForce()), np.array(r.getFtRawWrench())
    assert np.linalg.norm(force[:3]) < 40.0  # no contact: friction and model error only
    assert np.linalg.norm(raw[:3]) == pytest.approx(np.linalg.norm(force[:3]), rel=0.2, abs=1.0)


def test_unknown_variable_is_not_found():
    with pytest.raises(RuntimeError, match="not found"):
        rtde_receive.RTDEReceiveInterface(ADDRESS, variables=["actual_q", "no_such_variable"])


def test_io_interface_writes_show_in_the_outputs(world):
    io = rtde_io.RTDEIOInterface(ADDRESS)
    r = rtde_receive.RTDEReceiveInterface(ADDRESS, variables=[
        "timestamp", "actual_digital_output_bits", "target_speed_fraction", "standard_analog_output1"])
    raw = RawRTDE()
    try:
        assert io.setStandardDigitalOut(3, True) and io.setConfigurableDigitalOut(1, True)
        assert io.setSpeedSlider(0.25) and io.setAnalogOutputVoltage(1, 0.5)
        # (int register 18 is the emulated control-loop program's flag: a write would start it moving the arm)
        assert io.setInputIntRegister(20, -7) and io.setInputDoubleRegister(19, 2.5)
        time.sleep(0.05)
        assert r.getActualDigitalOutputBits() == (1 << 3) | (1 << 9)
        assert r.getTargetSpeedFraction() == 0.25 and r.getStandardAnalogOutput1() == 0.5
        raw.ask("V", struct.pack(">H", 2))  # input registers, as an output recipe reports them
        raw.ask("O", struct.pack(">d", 10.0) + b"input_int_register_20,input_double_register_19")
        raw.ask("S")
        cmd, data = raw.recv()
        assert cmd == "U" and struct.unpack(">Bid", data) == (1, -7, 2.5)
        assert io.setStandardDigitalOut(3, False)
        time.sleep(0.05)
        assert r.getActualDigitalOutputBits() == 1 << 9
    finally:
        raw.close()
        io.disconnect()
        r.disconnect()


def test_dashboard_state_shows_in_rtde(world, receive):
    d = dashboard_client.DashboardClient(ADDRESS)
    d.connect()
    try:
        assert d.polyscopeVersion() == "5.9.0.0"
        assert d.getSerialNumber() == "20205500001"
        assert (d.robotmode(), d.safetymode()) == ("Robotmode: RUNNING", "Safetymode: NORMAL")
        before = len(world.applied())
        d.pause()
        time.sleep(0.05)
        assert receive.getRuntimeState() == D.RUNTIME_PAUSED
        d.stop()
        time.sleep(0.05)
        assert receive.getRuntimeState() == D.RUNTIME_STOPPED
        assert [a.kind for a in world.applied()[before:]] == ["stop", "stop"]
        with pytest.raises(RuntimeError, match="Failed to execute: stop"):
            d.stop()  # already stopped
        d.powerOff()
        time.sleep(0.05)
        assert (receive.getRobotMode(), receive.getJointMode(), receive.getRobotStatus()) == (3, [239] * 6, 0)
        d.powerOn()
        time.sleep(0.05)
        assert receive.getRobotMode() == D.ROBOT_IDLE and d.robotmode() == "Robotmode: IDLE"
        d.brakeRelease()
        d.play()
        time.sleep(0.05)
        assert (receive.getRobotMode(), receive.getRuntimeState(), receive.getRobotStatus()) == (7, 2, 3)
        assert d.running()
    finally:
        d.disconnect()


class RawRTDE:
    """A minimal RTDE client to send what ur_rtde never does."""

    def __init__(self) -> None:
        self.sock = socket.create_connection((ADDRESS, D.RTDE_PORT), timeout=1.0)

    def send(self, cmd: str, payload: bytes = b"") -> None:
        self.sock.sendall(struct.pack(">HB", len(payload) + 3, ord(cmd)) + payload)

    def _n(self, n: int) -> bytes:
        buf = b""
        while len(buf) < n:
            buf += self.sock.recv(n - len(buf))
        return buf

    def recv(self) -> tuple[str, bytes]:
        size, cmd = struct.unpack(">HB", self._n(3))
        return chr(cmd), self._n(size - 3)

    def ask(self, cmd: str, payload: bytes = b"") -> tuple[str, bytes]:
        self.send(cmd, payload)
        return self.recv()

    def close(self) -> None:
        self.sock.close()


def test_raw_protocol_refusals_and_text_messages(world):
    a, b = RawRTDE(), RawRTDE()
    try:
        assert a.ask("V", struct.pack(">H", 1)) == ("V", b"\x00")  # v2 only
        assert a.ask("V", struct.pack(">H", 2)) == ("V", b"\x01")
        assert a.ask("v") == ("v", struct.pack(">IIII", 5, 9, 0, 0))
        assert a.ask("O", struct.pack(">d", 1000.0) + b"actual_q") == ("O", b"\x00VECTOR6D")  # > 500 Hz
        assert a.ask("O", struct.pack(">d", 10.0) + b"actual_q,bogus")[1] == b"\x00VECTOR6D,NOT_FOUND"
        assert a.ask("O", struct.pack(">d", 10.0) + b"timestamp,joint_mode,") == ("O", b"\x01DOUBLE,VECTOR6INT32")
        assert a.ask("I", b"input_int_register_30,speed_slider_mask") == ("I", b"\x01INT32,UINT32")
        assert b.ask("I", b"input_int_register_30") == ("I", b"\x00IN_USE")
        cmd, text = a.ask("U", b"\x07\x00")  # no input recipe 7
        assert cmd == "M" and b"unknown input recipe" in text
        cmd, text = a.ask("Z")
        assert cmd == "M" and b"unknown RTDE command" in text
        assert a.ask("S") == ("S", b"\x01")
        cmd, data = a.recv()
        assert cmd == "U" and data[0] == 1 and len(data) == 1 + 8 + 24
        a.close()
        time.sleep(0.1)
        assert b.ask("I", b"input_int_register_30") == ("I", b"\x01INT32")  # released with a's connection
    finally:
        a.close()
        b.close()


def test_an_e_series_recipe_at_500_hz_gets_every_packet_of_the_500_hz_grid(world):
    """Read off the socket (ur_rtde keeps only the newest packet): one packet per 2 ms of controller time,
    none skipped, with the F/T outputs of the recipe in each."""
    raw = RawRTDE()
    try:
        raw.ask("V", struct.pack(">H", 2))
        assert raw.ask("O", struct.pack(">d", 500.0) + b"timestamp,ft_raw_wrench,actual_TCP_force")[1][0] == 1
        raw.ask("S")
        rows = []
        end = time.monotonic() + 0.5
        while time.monotonic() < end:
            cmd, data = raw.recv()
            assert cmd == "U"
            rows.append(struct.unpack(">B13d", data))
    finally:
        raw.close()
    ticks = np.array([r[1] for r in rows]) * 500.0
    assert len(rows) > 150 and np.allclose(ticks, np.round(ticks), atol=1e-6)
    assert np.array_equal(np.diff(np.round(ticks)), np.ones(len(rows) - 1))
    assert np.all(np.isfinite(np.array([r[2:] for r in rows])))


def test_cb3_controller_streams_at_125_hz(world):
    world.restart("arm", {"address": ADDRESS, "controller_version": "3.15", "frequency": 125.0})
    try:
        r = rtde_receive.RTDEReceiveInterface(ADDRESS)
        ts, _ = collect(r, 0.5)
        r.disconnect()
        ticks = np.array(ts) / 0.008
        assert len(ts) > 20 and np.allclose(ticks, np.round(ticks), atol=1e-6)
        assert np.min(np.diff(ts)) == pytest.approx(0.008)
    finally:
        world.restart("arm", {"address": ADDRESS})


def test_refuses_non_loopback_addresses():
    with pytest.raises(ValueError, match="loopback"):
        UREmulator(DEVICE, SCENE, None, {"address": "192.0.2.7"})
    with pytest.raises(ValueError, match="at most 125 Hz"):
        UREmulator(DEVICE, SCENE, None, {"address": ADDRESS, "controller_version": "3.15"})


def test_an_arm_emulator_refuses_faults_it_cannot_inject():
    # the arms are emulators on the common base: its options, and no fault injection on their wire
    assert issubclass(UREmulator, Emulator) and issubclass(DynamixelEmulator, Emulator)
    with pytest.raises(ValueError, match="not supported"):
        UREmulator(DEVICE, SCENE, None, {"address": ADDRESS, "faults": {"drop": 0.1}})
    dxl = load_scene("dxl-arm")
    arm = next(d for d in dxl.devices if d.kind == "dynamixel")
    with pytest.raises(ValueError, match="not supported"):
        DynamixelEmulator(arm, dxl, None, {"faults": {"drop": 0.1}})
