"""DYNAMIXEL Protocol 2.0 framing and the emulated control table, without processes.

Packet vectors are the ROBOTIS e-manual's (Protocol 2.0 page examples); stuffing is compared with
dynamixel_sdk's own addStuffing/removeStuffing.
"""
from __future__ import annotations

import random

import numpy as np
import pytest
from dynamixel_sdk.protocol2_packet_handler import Protocol2PacketHandler

from ftc_hw.codecs import dxl_table as T
from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.dxl_protocol import PacketReader, crc16, fast_status, packet, parse_status, status, unstuff
from ftc_hw.sim_devices.dynamixel import DxlBus, WorldPort, build_servos

pytestmark = pytest.mark.compute  # computes only (nothing timed): runs with the others on every core

# -- framing -------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("built", "hex_"), [
    (lambda: packet(1, T.PING), "FFFFFD0001030001194E"),
    (lambda: status(1, 0, bytes([0x06, 0x04, 0x26])), "FFFFFD000107005500060426655D"),
    (lambda: packet(1, T.READ, bytes.fromhex("84000400")), "FFFFFD0001070002840004001D15"),
    (lambda: status(1, 0, bytes.fromhex("A6000000")), "FFFFFD000108005500A60000008CC0"),
    (lambda: packet(1, T.WRITE, bytes.fromhex("740000020000")), "FFFFFD0001090003740000020000CA89"),
    (lambda: packet(0xFE, T.SYNC_READ, bytes.fromhex("840004000102")), "FFFFFD00FE090082840004000102CEFA"),
    (lambda: status(2, 0, bytes.fromhex("1F080000")), "FFFFFD0002080055001F080000BABE"),
    (lambda: packet(1, T.REBOOT), "FFFFFD0001030008 2F4E"),
    (lambda: status(1, 0), "FFFFFD0001040055 00A10C"),
])
def test_packets_match_the_e_manual_examples(built, hex_):
    assert built() == bytes.fromhex(hex_.replace(" ", ""))


def test_stuffing_matches_dynamixel_sdk_both_ways():
    ph = Protocol2PacketHandler()
    rng = random.Random(7)
    stuffed_seen = 0
    for _ in range(2000):
        params = bytes(rng.choice([0xFF, 0xFD, 0x00, 0x12]) for _ in range(rng.randint(0, 12)))
        inst = rng.choice([T.WRITE, 0x55])
        tx = [0] * (len(params) + 10)
        tx[4], tx[5], tx[6], tx[7] = 7, (len(params) + 3) & 0xFF, (len(params) + 3) >> 8, inst
        tx[8:8 + len(params)] = list(params)
        sdk = ph.addStuffing(list(tx))
        total = (sdk[5] | sdk[6] << 8) + 7
        sdk[0:4] = [0xFF, 0xFF, 0xFD, 0x00]
        crc = ph.updateCRC(0, sdk, total - 2)
        sdk[total - 2:total] = [crc & 0xFF, crc >> 8]
        ours = packet(7, inst, params)
        assert ours == bytes(sdk[:total])
        stuffed_seen += len(ours) > len(params) + 10
        (got,) = PacketReader().feed(ours)
        assert got.crc_ok and got.instruction == inst and got.params == params
        st = status(3, 0, params)
        assert parse_status(st) == (3, 0, params)
        if st.count(b"\xfd\xfd") <= 1:  # the SDK mis-removes a second stuffing after a first one
            rx = ph.removeStuffing(list(st))
            assert bytes(rx[9:9 + (rx[5] | rx[6] << 8) - 4]) == params
    assert stuffed_seen > 100


def test_unstuff_keeps_a_genuine_fd_after_the_stuffing():
    assert unstuff(bytes.fromhex("FFFFFDFDFD")) == bytes.fromhex("FFFFFDFD")


def test_fast_status_blocks_carry_the_running_crc():
    blocks = [(0, 11, bytes(range(10))), (0x80, 12, bytes(range(10, 20)))]
    frame = fast_status(blocks)
    assert frame[:8] == bytes.fromhex("FFFFFD00FE1D0055")
    assert len(frame) == 7 + (frame[5] | frame[6] << 8)
    first_end = 8 + 2 + 10
    assert crc16(frame[:first_end]) == frame[first_end] | frame[first_end + 1] << 8
    assert crc16(frame[:-2]) == frame[-2] | frame[-1] << 8
    assert frame[first_end + 2:first_end + 4] == bytes([0x80, 12])


def test_reader_skips_garbage_reports_crc_errors_and_resyncs():
    good = packet(5, T.PING)
    bad = bytearray(packet(6, T.READ, bytes.fromhex("84000400")))
    bad[-1] ^= 0x55
    r = PacketReader()
    out = r.feed(b"\x00\xff\x13" + bytes(bad) + good[:6])
    assert [(i.id, i.crc_ok) for i in out] == [(6, False)]
    out = r.feed(good[6:])
    assert [(i.id, i.instruction, i.crc_ok) for i in out] == [(5, T.PING, True)]
    assert r.skipped >= 3


def test_reader_finds_a_packet_swallowed_by_a_truncated_one():
    truncated = packet(1, T.WRITE, bytes.fromhex("4000" + "01"))[:-4]
    good = packet(2, T.PING)
    out = PacketReader().feed(truncated + good + bytes(8))
    assert (2, T.PING, True) in [(i.id, i.instruction, i.crc_ok) for i in out]


def test_reader_expire_drops_an_incomplete_packet():
    r = PacketReader()
    assert r.feed(packet(1, T.PING)[:5]) == []
    assert r.pending
    r.expire()
    assert not r.pending and r.feed(packet(1, T.PING))[0].id == 1


# -- control table rules and the bus, with a fake world ----------------------------------------------------
class FakeWorld(WorldPort):
    def __init__(self, q):
        super().__init__(None, len(q), "arm")
        self.q = np.array(q, dtype=float)
        self.qd = np.zeros(len(q))
        self.cur = np.zeros(len(q))

    def state(self):
        return 1.0, self.q, self.qd, self.cur


@pytest.fixture
def chain():
    scene = load_scene("dxl-arm")
    device = next(d for d in scene.devices if d.kind == "dynamixel")
    world = FakeWorld([0.1, -0.2, 0.3, -0.4, 0.5])
    bus = DxlBus(build_servos(device, scene.n_joints, {}), world, reboot_s=0.05)
    return bus, world


def ask(bus, dxl_id, inst, params=b""):
    replies = []
    for ins in PacketReader().feed(packet(dxl_id, inst, params)):
        replies += bus.handle(ins)
    bus.flush()
    return [parse_status(frame) for _, frame in replies]


def u32(v):
    return int(v).to_bytes(4, "little", signed=v < 0)


def test_present_position_follows_the_joint_convention(chain):
    bus, world = chain
    world.cur[:] = [0.5, 0.0, 0.0, -0.269, 0.0]
    world.qd[:] = [0.0, 0.23981, 0.0, 0.0, 0.0]
    [(i, err, data)] = ask(bus, 11, T.READ, (126).to_bytes(2, "little") + (10).to_bytes(2, "little"))
    assert (i, err) == (11, 0)
    cur, vel, pos = (int.from_bytes(data[0:2], "little", signed=True), int.from_bytes(data[2:6], "little", signed=True),
                     int.from_bytes(data[6:10], "little", signed=True))
    assert pos == 2048 + round(0.1 / (2 * np.pi / 4096)) and vel == 0 and cur == round(0.5 / 0.00269)
    [(_, _, d12)] = ask(bus, 12, T.READ, bytes([128, 0, 4, 0]))
    assert int.from_bytes(d12, "little", signed=True) == 10  # 0.23981 rad/s = 10 x 0.229 rpm
    # the gripper servo turns the other way: + opens, its ticks go down
    [(_, _, d15)] = ask(bus, 15, T.READ, bytes([132, 0, 4, 0]))
    assert int.from_bytes(d15, "little", signed=True) == 2048 - round(0.5 / (2 * np.pi / 4096))


@pytest.mark.parametrize(("address", "data", "error"), [
    (11, b"\x04", T.ERR_ACCESS),  # Operating Mode is EEPROM: locked while torque is on
    (132, u32(5), T.ERR_ACCESS),  # Present Position is read-only
    (14, b"\x00", T.ERR_ACCESS),  # reserved byte
    (116, b"\x00\x08", T.ERR_DATA_LENGTH),  # half of Goal Position
    (116, u32(4096), T.ERR_DATA_LIMIT),  # beyond Max Position Limit in position mode
    (65, b"\x02", T.ERR_DATA_RANGE),  # LED is 0..1
    (102, (2000).to_bytes(2, "little"), T.ERR_DATA_LIMIT),  # Goal Current beyond Current Limit
])
def test_write_errors_follow_the_protocol(chain, address, data, error):
    bus, _ = chain
    before = bytes(bus.servos[0].mem)
    [(_, err, _)] = ask(bus, 11, T.WRITE, address.to_bytes(2, "little") + data)
    assert err == error
    assert bytes(bus.servos[0].mem[:64]) == before[:64]


def test_goal_write_drives_the_world_with_every_joint(chain):
    bus, world = chain
    [(_, err, _)] = ask(bus, 12, T.WRITE, (116).to_bytes(2, "little") + u32(2048 + 512))
    assert err == 0
    (cmd,) = world.sent
    assert cmd.kind == "goal"
    assert cmd.q == pytest.approx((0.1, 512 * 2 * np.pi / 4096, 0.3, -0.4, 0.5), abs=1e-3)


def test_torque_off_then_on_tells_the_world_once_and_holds_present(chain):
    bus, world = chain
    sync = bytes([64, 0, 1, 0]) + b"".join(bytes([i, 0]) for i in (11, 12, 13, 14, 15))
    ask(bus, T.BROADCAST_ID, T.SYNC_WRITE, sync)
    assert [(c.kind, c.on) for c in world.sent] == [("torque", False)]
    ask(bus, 11, T.WRITE, bytes([64, 0, 1]))
    world.q[0] = 0.2
    ask(bus, 12, T.WRITE, bytes([64, 0, 1]))
    assert [(c.kind, c.on) for c in world.sent] == [("torque", False), ("torque", True)]
    [(_, _, goal)] = ask(bus, 11, T.READ, bytes([116, 0, 4, 0]))
    assert int.from_bytes(goal, "little") == 2048 + round(0.1 / (2 * np.pi / 4096))


def test_unknown_instruction_crc_error_and_bad_length(chain):
    bus, _ = chain
    assert ask(bus, 11, 0x77)[0][1] == T.ERR_INSTRUCTION
    assert ask(bus, 11, T.READ, b"\x84\x00")[0][1] == T.ERR_DATA_LENGTH
    assert ask(bus, 11, T.ACTION)[0][1] == T.ERR_INSTRUCTION  # no reg write pending
    bad = bytearray(packet(11, T.PING))
    bad[-2] ^= 1
    (ins,) = PacketReader().feed(bytes(bad))
    [(_, frame)] = bus.handle(ins)
    assert parse_status(frame)[:2] == (11, T.ERR_CRC)
    bad = bytearray(packet(T.BROADCAST_ID, T.PING))
    bad[-2] ^= 1
    (ins,) = PacketReader().feed(bytes(bad))
    assert bus.handle(ins) == []  # nobody answers a damaged broadcast


def test_reg_write_then_action(chain):
    bus, world = chain
    assert ask(bus, 13, T.REG_WRITE, (116).to_bytes(2, "little") + u32(2000))[0][1] == 0
    assert ask(bus, 13, T.READ, bytes([69, 0, 1, 0]))[0][2] == b"\x01"
    assert world.sent == []
    assert ask(bus, 13, T.ACTION)[0][1] == 0
    assert world.sent[-1].kind == "goal"
    assert ask(bus, 13, T.READ, bytes([69, 0, 1, 0]))[0][2] == b"\x00"


def test_indirect_address_maps_present_position(chain):
    bus, _ = chain
    for k in range(4):  # Indirect Address 1..4 -> Present Position bytes
        assert ask(bus, 11, T.WRITE, (168 + 2 * k).to_bytes(2, "little") + (132 + k).to_bytes(2, "little"))[0][1] == 0
    [(_, _, via)] = ask(bus, 11, T.READ, bytes([224, 0, 4, 0]))
    [(_, _, direct)] = ask(bus, 11, T.READ, bytes([132, 0, 4, 0]))
    assert via == direct


def test_status_return_level_and_broadcast_silence(chain):
    bus, _ = chain
    assert ask(bus, T.BROADCAST_ID, T.WRITE, bytes([65, 0, 1])) == []
    ask(bus, 11, T.WRITE, bytes([68, 0, 1]))  # level 1: reads and pings only
    assert ask(bus, 11, T.WRITE, bytes([65, 0, 0])) == []
    assert len(ask(bus, 11, T.READ, bytes([65, 0, 1, 0]))) == 1
    assert [r[0] for r in ask(bus, T.BROADCAST_ID, T.PING)] == [11, 12, 13, 14, 15]


def test_hardware_error_sets_the_alert_bit_blocks_torque_until_reboot():
    scene = load_scene("dxl-arm")
    device = next(d for d in scene.devices if d.kind == "dynamixel")
    world = FakeWorld([0.0] * 5)
    bus = DxlBus(build_servos(device, 5, {"hardware_error": {"12": T.HW_OVERLOAD}}), world, reboot_s=0.0)
    [(_, err, _)] = ask(bus, 12, T.PING)
    assert err == T.ERR_ALERT
    assert ask(bus, 12, T.WRITE, bytes([64, 0, 1]))[0][1] == T.ERR_ALERT | T.ERR_RESULT_FAIL
    assert ask(bus, 11, T.PING)[0][1] == 0
    assert ask(bus, 12, T.REBOOT)[0][1] == T.ERR_ALERT  # answered before rebooting
    assert ask(bus, 12, T.PING)[0][1] == 0
    assert ask(bus, 12, T.WRITE, bytes([64, 0, 1]))[0][1] == 0


def test_sync_and_bulk_reads_answer_in_order(chain):
    bus, _ = chain
    out = ask(bus, T.BROADCAST_ID, T.SYNC_READ, bytes([132, 0, 4, 0, 14, 12, 99]))
    assert [r[0] for r in out] == [14, 12]  # 99 does not exist: nobody answers for it
    out = ask(bus, T.BROADCAST_ID, T.BULK_READ, bytes([11, 132, 0, 4, 0, 13, 146, 0, 1, 0]))
    assert [(r[0], len(r[2])) for r in out] == [(11, 4), (13, 1)]
