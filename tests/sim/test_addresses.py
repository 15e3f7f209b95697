"""``ftc sim --address DEVICE=ADDR``: the emulator options that put each device where it is asked to be;
servers on loopback addresses only."""
from __future__ import annotations

import pytest

from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.addresses import emulator_address, parse_addresses

pytestmark = pytest.mark.realtime  # against the wall clock: ./run-tests runs it alone, after the others


def test_each_kind_gets_its_own_kind_of_address():
    scene = load_scene("ur5e")
    assert parse_addresses(["arm=127.0.0.3", "ft=/tmp/can.tty"], scene) == {
        "arm": {"address": "127.0.0.3"}, "ft": {"path": "/tmp/can.tty"}}
    assert emulator_address("ft300", "modbus-tcp", "127.0.0.5:1502") == {"host": "127.0.0.5", "port": 1502}
    assert emulator_address("modbus-ft", "modbus-tcp", "127.0.0.5") == {"host": "127.0.0.5"}


@pytest.mark.parametrize(("text", "pattern"), [
    ("arm=192.0.2.7", "loopback addresses only"),
    ("arm=localhost", "not an IP address"),
    ("ft=can.tty", "absolute path"),
    ("gripper=127.0.0.3", "no device 'gripper' \\(devices: ft, arm\\)"),
    ("arm", "expected DEVICE=ADDR"),
])
def test_bad_addresses_are_refused(text, pattern):
    with pytest.raises(ValueError, match=pattern):
        parse_addresses([text], load_scene("ur5e"))
