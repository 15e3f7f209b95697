"""Clients we did not write against our emulators, each client in a process of its own (the emulator runs in
another, the world in a third): ``dynamixel-python`` (module ``dxl2``, its own packet code, not
dynamixel_sdk) against the DYNAMIXEL chain, ``minimalmodbus`` (Modbus RTU) against the FT 300. Their
values must equal our adapters' within one count.

dxl2 0.0.8 works on the emulator's pty path (pyserial opens it). One bug of its own, not hit here:
``InstructionPacket`` computes the CRC over byte-stuffed params but sends the params unstuffed (and LEN
counts them unstuffed), so an instruction whose params hold ``FF FF FD`` gets a CRC Error status from a
servo (docs/arms.md). minimalmodbus 2.1.1 works on the pty path as it is.
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
import time

import numpy as np
import pytest

from ftc_hw.bus import Bus
from ftc_hw.codecs.dxl_table import MODELS
from ftc_hw.devices.registry import make_adapter
from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.host import WorldHost

pytestmark = [pytest.mark.realtime, pytest.mark.timeout(120)]

SCENE = load_scene("dxl-arm")
ARM = next(d for d in SCENE.devices if d.kind == "dynamixel")
RAD = 2 * math.pi / 4096
CONSTANT = np.array([12.34, -56.78, 199.99, 1.234, -2.345, 0.012])

DXL2_CLIENT = r"""
import json, sys
from dxl2.v2 import MotorBus
path, baud, ids = sys.argv[1], int(sys.argv[2]), json.loads(sys.argv[3])
bus = MotorBus(path, baud, timeout=0.5)
bus.connect()
out = {"ping": {}, "position": {}, "current": {}}
for i in ids:
    for _ in range(5):  # a loaded machine may miss a timeout once
        r = bus.ping(i)
        if r.ok:
            break
    out["ping"][i] = r.data
    out["position"][i] = bus.read(i, 132, 4, signed=True).data
    out["current"][i] = bus.read(i, 126, 2, signed=True).data
if sys.argv[4] == "write":
    goal = out["position"][ids[0]] + 50
    w = bus.write(ids[0], 116, 4, goal, signed=True)
    out["write_ok"], out["goal"], out["goal_read"] = w.ok, goal, bus.read(ids[0], 116, 4, signed=True).data
bus.disconnect()
print(json.dumps(out))
"""

MINIMALMODBUS_CLIENT = r"""
import json, sys
import minimalmodbus
ft = minimalmodbus.Instrument(sys.argv[1], 9)
ft.serial.baudrate = 19200
ft.serial.timeout = 0.5
s16 = lambda v: v - 65536 if v >= 32768 else v
out = {
    "wrench": [s16(v) for v in ft.read_registers(180, 6, functioncode=3)],
    "firmware": ft.read_registers(500, 3, functioncode=3),
    "serial": ft.read_registers(510, 4, functioncode=3),
    "year": ft.read_register(514, 0, functioncode=3),
}
try:
    ft.read_register(300, 0, functioncode=3)
    out["unmapped"] = "answered"
except minimalmodbus.IllegalRequestError as exc:
    out["unmapped"] = type(exc).__name__
print(json.dumps(out))
"""


def _client(script: str, *args: str) -> dict:
    done = subprocess.run([sys.executable, "-c", script, *args], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def _adapter_frames(spec, endpoint, topic_frames: int = 20, scene=SCENE) -> tuple:
    bus = Bus()
    adapter = make_adapter(spec, bus, endpoint, scene=scene)
    with adapter:
        assert adapter.wait_connected(10.0)
        sub = bus.subscribe(adapter.topic, maxsize=10_000)
        got: list = []
        end = time.monotonic() + 5.0
        while len(got) < topic_frames and time.monotonic() < end:
            time.sleep(0.05)
            got += sub.drain()
    assert len(got) >= topic_frames
    return adapter, got


def test_dxl2_pings_reads_and_writes_what_our_adapter_reads():
    ids = list(ARM.params["ids"])
    model = MODELS[ARM.params["model"]]
    with WorldHost(SCENE, "hold", devices=[ARM.name], noise=False) as w:
        time.sleep(1.0)  # the held arm settles
        path = w.endpoint(ARM.name)["endpoint"]
        theirs = _client(DXL2_CLIENT, path, str(ARM.params["baudrate"]), json.dumps(ids), "read")
        _, frames = _adapter_frames(ARM, w.endpoint(ARM.name))
        before = w.applied_count()
        wrote = _client(DXL2_CLIENT, path, str(ARM.params["baudrate"]), json.dumps(ids), "write")
        goals = [a for a in w.applied(before) if a.kind == "goal"]
    assert theirs["ping"] == {str(i): {"model_number": model.model_number, "firmware_version": 46} for i in ids}
    f = frames[-1]
    zeros, dirs = ARM.params["zero_ticks"], ARM.params["directions"]
    for j, i in enumerate(ids):
        ours = zeros[j] + dirs[j] * f.q[j] / RAD
        assert abs(theirs["position"][str(i)] - ours) <= 1.0, (i, theirs["position"][str(i)], ours)
        ours_current = dirs[j] * f.current[j] / model.current_unit_a
        assert abs(theirs["current"][str(i)] - ours_current) <= 1.0, (i, theirs["current"][str(i)], ours_current)
    assert wrote["write_ok"] and wrote["goal_read"] == wrote["goal"]
    assert goals, "dxl2's Goal Position write never reached the world"
    assert goals[-1].q[0] == pytest.approx(dirs[0] * (wrote["goal"] - zeros[0]) * RAD, abs=1e-9)


def test_minimalmodbus_reads_the_ft300_registers_our_adapter_reads(ft_sim):
    scene, spec = ft_sim.device("dxl-arm", "ft300")
    world = ft_sim.world(100.0, n_joints=4, fn=lambda k: CONSTANT.copy())
    emu = ft_sim.start_emulator(spec, scene, world)
    theirs = _client(MINIMALMODBUS_CLIENT, emu.endpoint["endpoint"])
    adapter, frames = _adapter_frames(spec, emu.endpoint, scene=scene)
    counts = np.round(frames[-1].wrench * np.array([100, 100, 100, 1000, 1000, 1000]))
    assert np.all(np.abs(np.array(theirs["wrench"]) - counts) <= 1), (theirs["wrench"], counts)
    fw = theirs["firmware"]
    text = bytes([fw[0] >> 8, fw[0] & 0xFF, fw[1] >> 8]).decode()
    assert f"{text}-{fw[1] & 0xFF}.{fw[2] >> 8}.{fw[2] & 0xFF}" == adapter.identity["firmware"]
    sn = theirs["serial"]
    number = (sn[3] >> 8) << 24 | (sn[3] & 0xFF) << 16 | (sn[2] >> 8) << 8 | (sn[2] & 0xFF)
    assert f"{bytes([sn[0] >> 8, sn[0] & 0xFF, sn[1] >> 8]).decode()}-{number:04d}" == adapter.identity["serial"]
    assert str(theirs["year"]) == adapter.identity["year"]
    assert theirs["unmapped"] == "IllegalRequestError"  # exception 02, illegal data address
