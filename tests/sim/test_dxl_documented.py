"""The DYNAMIXEL emulator's replies byte for byte where the ROBOTIS e-Manual (Protocol 2.0) fixes them, and
bad input answered as it says, or not at all, never a crash.

The examples are the e-Manual's, for an XM430-W210 with ID 1 (model 1030, firmware 0x26): Ping, Read of
Present Position (132, 4 bytes, value 166), Write of Goal Position (116) = 512. Error numbers (status
packet ERR field): 0x02 Instruction Error (an undefined instruction), 0x03 CRC Error. A packet whose
rest never comes is dropped after the packet timeout, unanswered; a packet to another ID is unanswered.
The CRCs of the replies that the e-Manual does not print are checked with dynamixel_sdk's ``updateCRC``
(ROBOTIS's own code), not with ours. Sources: sim_devices/SOURCES.md.
"""
from __future__ import annotations

import math

import pytest
from dynamixel_sdk.protocol2_packet_handler import Protocol2PacketHandler

from ftc_hw.codecs import dxl_table as T
from ftc_hw.sim_devices.dxl_protocol import PacketReader
from ftc_hw.sim_devices.dxl_servo import Servo
from ftc_hw.sim_devices.dynamixel import DxlBus

from .test_dxl_protocol import FakeWorld

pytestmark = pytest.mark.compute  # computes only (nothing timed): runs with the others on every core

PING = "FF FF FD 00 01 03 00 01 19 4E"
PING_STATUS = "FF FF FD 00 01 07 00 55 00 06 04 26 65 5D"
READ_132 = "FF FF FD 00 01 07 00 02 84 00 04 00 1D 15"
READ_STATUS = "FF FF FD 00 01 08 00 55 00 A6 00 00 00 8C C0"
WRITE_GOAL_512 = "FF FF FD 00 01 09 00 03 74 00 00 02 00 00 CA 89"
WRITE_STATUS = "FF FF FD 00 01 04 00 55 00 A1 0C"


@pytest.fixture
def bus():
    """One XM430-W210, ID 1, firmware 0x26, at tick 166 (the e-Manual's Read example)."""
    model = T.MODELS["XM430-W210"]
    servo = Servo(model, 1, 0, eeprom={"Firmware Version": 0x26})
    world = FakeWorld([(166 - model.center_tick) * 2 * math.pi / 4096])
    return DxlBus([servo], world)


def ask(bus: DxlBus, hex_: str | bytes) -> bytes:
    """What the bus answers to the bytes (whole packets; a fragment is held, as on the line)."""
    data = bytes.fromhex(hex_) if isinstance(hex_, str) else hex_
    out = b""
    for ins in PacketReader().feed(data):
        out += b"".join(frame for _, frame in bus.handle(ins))
    bus.flush()
    return out


def sdk_crc_ok(frame: bytes) -> bool:
    crc = Protocol2PacketHandler().updateCRC(0, list(frame[:-2]), len(frame) - 2)
    return crc == int.from_bytes(frame[-2:], "little")


def test_the_e_manual_examples_byte_for_byte(bus):
    assert ask(bus, PING) == bytes.fromhex(PING_STATUS)
    assert ask(bus, READ_132) == bytes.fromhex(READ_STATUS)
    assert ask(bus, WRITE_GOAL_512) == bytes.fromhex(WRITE_STATUS)
    assert bus.servos[0].get("Goal Position") == 512


def test_unknown_instruction_gets_an_instruction_error(bus):
    frame = bytearray(bytes.fromhex("FF FF FD 00 01 03 00 77"))
    crc = Protocol2PacketHandler().updateCRC(0, list(frame), len(frame))
    reply = ask(bus, bytes(frame) + crc.to_bytes(2, "little"))
    assert reply[:9] == bytes.fromhex("FF FF FD 00 01 04 00 55 02") and len(reply) == 11 and sdk_crc_ok(reply)


def test_wrong_crc_gets_a_crc_error_and_a_broadcast_with_one_gets_none(bus):
    bad = bytearray(bytes.fromhex(PING))
    bad[-1] ^= 0x01
    reply = ask(bus, bytes(bad))
    assert reply[:9] == bytes.fromhex("FF FF FD 00 01 04 00 55 03") and len(reply) == 11 and sdk_crc_ok(reply)
    broadcast = bytearray(bytes.fromhex("FF FF FD 00 FE 03 00 01 31 42"))
    assert ask(bus, bytes(broadcast)) != b""  # a good broadcast ping is answered ...
    broadcast[-1] ^= 0x01
    assert ask(bus, bytes(broadcast)) == b""  # ... a damaged one by nobody


def test_short_packets_other_ids_and_garbage_get_nothing_then_the_bus_still_answers(bus):
    reader = PacketReader()
    assert reader.feed(bytes.fromhex(PING)[:7]) == [] and reader.pending  # waits for the rest
    reader.expire()  # the packet timeout: dropped, unanswered
    assert not reader.pending
    assert ask(bus, "FF FF FD 00 01 02 00 01") == b""  # LEN 2: shorter than INST + CRC, no packet
    assert ask(bus, "FF FF FD 00 02 03 00 01 19 4E") == b""  # ID 2 (and a CRC for ID 1): nobody
    assert ask(bus, bytes(range(256)) * 4) == b""  # garbage
    assert ask(bus, "FF FF FD 00 01 07 00 02 84 00") == b""  # a Read cut short: held, no answer yet
    assert ask(bus, PING) == bytes.fromhex(PING_STATUS)
