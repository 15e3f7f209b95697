"""The FT 300 emulator's Modbus RTU replies byte for byte where the documents fix them, bad input answered
as they say (or not at all) without taking the emulator down, and a sensor left streaming by another
program, which answers no Modbus until jammed: our adapter stops the stream and gets data.

Sources (sim_devices/SOURCES.md): Modbus Application Protocol V1.1b3 (FC03 request and reply, exception
codes 01 illegal function, 02 illegal data address, 03 illegal data value for a quantity over 125),
Modbus over Serial Line V1.02 (CRC-16 low byte first; a frame with a wrong CRC is discarded, no reply;
a request to another unit gets none), Robotiq's FT 300 manual (unit 9, 19200 baud, registers 180-185,
the stream and its 0xFF "jam" stop). The CRCs below were computed with pymodbus and minimalmodbus, not
with our codec.
"""
from __future__ import annotations

import time

import numpy as np
import pytest
import serial
from pymodbus.framer.rtu import FramerRTU  # an independent CRC

from ftc_hw.bus import Bus
from ftc_hw.devices.registry import make_adapter

pytestmark = [pytest.mark.realtime, pytest.mark.timeout(60)]
CONSTANT = np.array([12.34, -56.78, 199.99, 1.234, -2.345, 0.012])

READ_180_185 = bytes.fromhex("09 03 00 b4 00 06 84 a6")
REPLY_180_185 = bytes.fromhex("09 03 0c 04 d2 e9 d2 4e 1f 04 d2 f6 d7 00 0c c8 40")  # 1234 -5678 19999 1234 -2345 12
READ_300 = bytes.fromhex("09 03 01 2c 00 01 45 77")
ILLEGAL_ADDRESS = bytes.fromhex("09 83 02 41 33")
WRITE_COIL = bytes.fromhex("09 05 00 00 ff 00 8d 72")  # FC05: the FT 300 has no coils
ILLEGAL_FUNCTION = bytes.fromhex("09 85 01 02 92")
READ_DEVICE_ID = bytes.fromhex("09 2b 0e 01 00 91 b6")  # FC43/14 (MEI): a function the FT 300 has not
ILLEGAL_FUNCTION_2B = bytes.fromhex("09 ab 01 1f 32")
READ_126_REGISTERS = bytes.fromhex("09 03 00 b4 00 7e 84 84")
ILLEGAL_VALUE = bytes.fromhex("09 83 03 80 f3")
START_STREAM = bytes.fromhex("09 10 01 9a 00 01 02 02 00")  # FC16: 0x0200 to register 410 (CRC added below)


def _emulator(ft_sim):
    scene, spec = ft_sim.device("dxl-arm", "ft300")
    world = ft_sim.world(100.0, n_joints=4, fn=lambda k: CONSTANT.copy())
    return scene, spec, ft_sim.start_emulator(spec, scene, world)


def _ask(port: serial.Serial, request: bytes, expect: int, wait: float = 0.3) -> bytes:
    port.reset_input_buffer()
    port.write(request)
    got = b""
    end = time.monotonic() + wait
    while len(got) < expect and time.monotonic() < end:
        got += port.read(expect - len(got))
    return got


def test_documented_replies_byte_for_byte_and_bad_input(ft_sim):
    _, _, emu = _emulator(ft_sim)
    with serial.Serial(emu.endpoint["endpoint"], 19200, timeout=0.05) as port:
        assert _ask(port, READ_180_185, len(REPLY_180_185)) == REPLY_180_185
        assert _ask(port, READ_300, len(ILLEGAL_ADDRESS)) == ILLEGAL_ADDRESS
        assert _ask(port, WRITE_COIL, len(ILLEGAL_FUNCTION)) == ILLEGAL_FUNCTION
        assert _ask(port, READ_126_REGISTERS, len(ILLEGAL_VALUE)) == ILLEGAL_VALUE
        bad_crc = READ_180_185[:-1] + bytes([READ_180_185[-1] ^ 1])
        assert _ask(port, bad_crc, 1) == b""  # discarded
        other_unit = bytes([10]) + READ_180_185[1:-2]
        other_unit += FramerRTU.compute_CRC(other_unit).to_bytes(2, "big")
        assert _ask(port, other_unit, 1) == b""  # another unit's request
        assert _ask(port, READ_180_185[:5], 1) == b""  # short: waits for the rest, then drops it
        time.sleep(0.1)  # longer than the inter-frame silence: the fragment is stale
        assert _ask(port, b"\x09\x2b\x0e\x01\x00", 1) == b""  # an unknown function's bytes without a CRC
        time.sleep(0.1)
        assert _ask(port, READ_DEVICE_ID, len(ILLEGAL_FUNCTION_2B)) == ILLEGAL_FUNCTION_2B  # whole, with its CRC
        assert _ask(port, READ_180_185, len(REPLY_180_185)) == REPLY_180_185  # still answering


@pytest.mark.parametrize("mode", ["stream", "poll"])
def test_adapter_copes_with_a_sensor_left_streaming(ft_sim, mode):
    """Another program started the stream and went away without the jam signal: the sensor answers no
    Modbus. Our adapter (either mode) jams it quiet, as Robotiq's driver does, then reads."""
    scene, spec, emu = _emulator(ft_sim)
    with serial.Serial(emu.endpoint["endpoint"], 19200, timeout=0.2) as port:
        port.write(START_STREAM + FramerRTU.compute_CRC(START_STREAM).to_bytes(2, "big"))
        time.sleep(0.2)
        assert port.read(200).count(b"\x20\x4e") >= 5  # streaming
        assert _ask(port, READ_180_185, len(REPLY_180_185), wait=0.2)[:3] != REPLY_180_185[:3]  # no Modbus
    spec = type(spec)(spec.name, spec.kind, spec.transport, spec.address, {**spec.params, "mode": mode})
    bus = Bus()
    adapter = make_adapter(spec, bus, emu.endpoint, scene=scene)
    with adapter:
        assert adapter.wait_connected(10.0)
        end = time.monotonic() + 3.0
        while len(bus.history(adapter.topic)) < 20 and time.monotonic() < end:
            time.sleep(0.05)
    frames = bus.history(adapter.topic)
    assert len(frames) >= 20
    assert np.allclose(frames[-1].wrench, CONSTANT, atol=1e-9)
    assert adapter.counters["jams"] >= 1
