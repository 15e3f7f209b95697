"""Recordings of the emulated UR arm as users make them (tests/record/test_ur_csv_emulated.py): the
UR emulator fed by the simulated world (a :class:`WorldHost`, ur5e's sweep), read through ur_rtde
(the real client library). ur_rtde's own ``startFileRecording`` writes one file (the real ur_rtde
format); what ur_rtde received, polled here, goes through our writer of UR's RTDE client format (UR's
client library is not on the package index: ``UrRtde``, ``rtde``, ``RTDE_Python_Client_Library``,
``ur-rtde-client``, ``UrRtdeClient`` are not found)."""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ftc_hw.record.ur_csv import UR_CLIENT, write_ur_csv
from ftc_hw.sim_devices.host import WorldHost
from ftc_hw.sim_devices.link import JointRecord

# what is recorded: the fields the reader uses, and some it must step over (integers, int vectors)
GETTERS = {
    "timestamp": "getTimestamp", "target_current": "getTargetCurrent", "target_moment": "getTargetMoment",
    "actual_q": "getActualQ", "actual_qd": "getActualQd", "actual_current": "getActualCurrent",
    "actual_TCP_force": "getActualTCPForce", "joint_temperatures": "getJointTemperatures",
    "robot_mode": "getRobotMode", "joint_mode": "getJointMode",
    "actual_digital_input_bits": "getActualDigitalInputBits",
    "runtime_state": "getRuntimeState", "ft_raw_wrench": "getFtRawWrench",
}
INTEGER = {"robot_mode", "joint_mode", "actual_digital_input_bits", "runtime_state"}


@dataclass
class EmulatedRecording:
    ur_rtde_csv: Path  # written by ur_rtde's startFileRecording
    ur_client_csv: Path  # our writer (UR's client format), from ``received``
    received: dict[str, np.ndarray]  # per field, what ur_rtde's getters returned, one row per new timestamp
    world: list[JointRecord]  # the world's joint samples over the recording


def _state(r) -> dict | None:
    """One consistent state: the getters read between two equal timestamps (a packet may land between)."""
    t = r.getTimestamp()
    values = {name: getattr(r, getter)() for name, getter in GETTERS.items()}
    return values if r.getTimestamp() == t == values["timestamp"] else None


def _poll(r, ring, n_joints: int, seconds: float) -> tuple[list[dict], list[JointRecord]]:
    """ur_rtde's new states, and the world's joint samples (drained as it goes: the ring is short)."""
    states: list[dict] = []
    world: list[JointRecord] = []
    end = time.monotonic() + seconds
    drained = time.monotonic()
    while time.monotonic() < end:
        if not states or r.getTimestamp() != states[-1]["timestamp"]:
            s = _state(r)
            if s is not None:
                states.append(s)
        if time.monotonic() - drained > 0.02:
            world += [JointRecord.from_row(row.copy(), n_joints) for row in ring.new()]
            drained = time.monotonic()
        time.sleep(0.0003)
    world += [JointRecord.from_row(row.copy(), n_joints) for row in ring.new()]
    return states, world


def record_emulated_arm(folder: Path, *, seconds: float = 2.0) -> EmulatedRecording:
    """Records ``seconds`` of ur5e's sweep both ways into ``folder``."""
    import rtde_receive  # lazy: only the real-time tests need the client library loaded

    variables = list(GETTERS)
    with WorldHost("ur5e", "sweep", devices=["arm"], noise=False) as world:
        ring = world.joint_reader()
        r = rtde_receive.RTDEReceiveInterface(world.endpoint("arm")["address"], 500.0, variables)
        try:
            rtde_file = folder / "ur_rtde.csv"
            assert r.startFileRecording(str(rtde_file), variables)
            states, world_rows = _poll(r, ring, world.scene.n_joints, seconds)
            r.stopFileRecording()
        finally:
            r.disconnect()
    received = {name: np.array([s[name] for s in states], dtype=np.int64 if name in INTEGER else float)
                for name in GETTERS}
    client_file = write_ur_csv(folder / "ur_client.csv", received, style=UR_CLIENT)
    return EmulatedRecording(rtde_file, client_file, received, world_rows)
