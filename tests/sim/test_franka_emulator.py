"""The Franka emulator read by the real client libraries, each in its own process (panda-python's
libfranka 0.9.2, protocol 5; pylibfranka's 0.21.3, protocol 10), the world in another, on the
built-in panda scene. Every emulator of this module binds 127.0.0.51 (libfranka
hard-codes port 1337): other modules use other loopback addresses."""
from __future__ import annotations

import json
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.host import WorldHost
from ftc_hw.sim_devices.link import JointRecord

pytestmark = pytest.mark.realtime  # against the wall clock: ./run-tests runs it alone, after the others

ADDRESS = "127.0.0.51"
SCENE = load_scene("panda")
CLIENT = Path(__file__).with_name("franka_client.py")


@pytest.fixture(scope="module")
def world():
    with WorldHost(SCENE, "sweep", devices=["arm"], options={"arm": {"address": ADDRESS}}, noise=False) as w:
        yield w


def run_client(client: str, count: int, reader=None) -> tuple[dict, dict[int, JointRecord]]:
    """The client's output, and the world's samples by controller tick (ms) while it ran: the first sample
    of each tick, as the emulator sends (read as they come: the ring holds about 2 s of the world)."""
    ticks: dict[int, JointRecord] = {}
    with tempfile.TemporaryFile("w+") as stdout:  # a file, not a pipe: the client's line outgrows a pipe's buffer
        proc = subprocess.Popen([sys.executable, str(CLIENT), client, ADDRESS, str(count)], stdout=stdout, text=True)
        try:
            deadline = time.monotonic() + 60.0
            while proc.poll() is None and time.monotonic() < deadline:
                for rec in reader.new() if reader is not None else ():
                    j = JointRecord.from_row(rec, SCENE.n_joints)
                    ticks.setdefault(math.floor(j.t * 1000 + 1e-6), j)
                time.sleep(0.1)
        finally:
            if proc.poll() is None:
                proc.kill()
            proc.wait(10)
        stdout.seek(0)
        out = stdout.read()
    assert proc.returncode == 0, out
    return json.loads(out.strip().splitlines()[-1]), ticks


@pytest.mark.parametrize(("client", "rtol"), [("panda-py", 0.0), ("pylibfranka", 1e-6)])  # v10 sends float32
def test_each_client_reads_the_world_joint_ring_and_stops_the_arm(world, client, rtol):
    world.restart("arm", {"address": ADDRESS, "client": client})
    reader = world.joint_reader()
    before = world.applied_count()
    out, ticks = run_client(client, 300, reader)
    states = out["states"]
    ms = [s[0] for s in states]  # which of the 1 kHz states the client reads depends on the host's load
    assert all(b > a for a, b in zip(ms, ms[1:], strict=False))
    matched = [(s, ticks[s[0]]) for s in states if s[0] in ticks]
    assert len(matched) >= 0.9 * len(states)
    for s, j in matched:
        np.testing.assert_allclose(s[1], j.q, rtol=rtol, atol=1e-6 if rtol else 0.0)
        np.testing.assert_allclose(s[2], j.tau_j, rtol=rtol, atol=1e-5 if rtol else 0.0)
        assert np.any(j.tau_j != 0.0)
    assert states[-1][3].endswith("Move")  # the scenario plays
    assert out["stop"] == "ok" and out["automatic_error_recovery"] == "ok"
    assert [a.kind for a in world.applied()[before:]] == ["stop", "resume"]


def test_a_library_of_the_other_protocol_version_is_refused_as_a_real_controller_does(world):
    world.restart("arm", {"address": ADDRESS, "client": "panda-py"})  # an FER system (protocol 5)
    out, _ = run_client("pylibfranka", 10)
    assert "connect_error" in out and "ncompatible" in out["connect_error"], out
