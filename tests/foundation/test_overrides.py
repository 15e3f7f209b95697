"""Pointing a scene at one's own devices: ``--device NAME.KEY=VALUE`` and rig files, typed and checked by
the device kind's schema; errors name the option or file, the device, the key and what is accepted."""
from __future__ import annotations

import re

import pytest

from ftc_hw.scene import SceneError, load_rig_scene, load_scene


def _device(scene, name):
    return next(d for d in scene.devices if d.name == name)


def test_device_options_set_the_address_and_typed_params():
    scene = load_rig_scene("ur5e", ["ft.channel=/dev/ttyACM0", "ft.base_id=0x10", "arm.address=192.168.1.10",
                                    "arm.frequency=125"])
    ft, arm = _device(scene, "ft"), _device(scene, "arm")
    assert ft.params["channel"] == "/dev/ttyACM0" and ft.params["base_id"] == 16
    assert ft.params["dbc"] == "ati_netft_can.dbc"  # the scene's other params stay
    assert arm.address == "192.168.1.10" and arm.params["frequency"] == 125.0
    assert load_scene("ur5e").devices[1].address is None  # the scene itself is untouched


def test_lists_and_booleans_parse():
    scene = load_rig_scene("dxl-arm", ["arm.ids=[1, 2, 3, 4, 5]", "arm.fast_read=true", "arm.baudrate=57600",
                                       "ft.address=/dev/ttyUSB1"])
    arm = _device(scene, "arm")
    assert arm.params["ids"] == [1, 2, 3, 4, 5] and arm.params["fast_read"] is True
    assert arm.params["baudrate"] == 57600 and _device(scene, "ft").address == "/dev/ttyUSB1"


@pytest.mark.parametrize(("option", "key", "pattern"), [
    ("ft.baud_rate=57600", "ft.baud_rate", r"accepted: address, transport, mode, device_id, baudrate.*"
                                           r"did you mean 'baudrate'\?"),
    ("ft.baudrate=fast", "ft.baudrate", r"expected an integer \(19200, 0x10\).*got 'fast'"),
    ("ft.device_id=0", "ft.device_id", r">= 1 and <= 247, got 0 \(out of range\)"),
    ("arm.baudrate=12345", "arm.baudrate", "one of 9600, 57600"),
    ("ft.transport=can", "ft.transport", "transport modbus-rtu, modbus-tcp, not 'can'"),
    ("gripper.address=/dev/x", "gripper.address", r"scene 'dxl-arm' has no device 'gripper' \(devices: ft, arm\)"),
    ("ft.address", "ft.address", "expected NAME.KEY=VALUE"),
    ("ft.identity=x", "ft.identity", "expected a table"),
])
def test_bad_device_options_say_what_is_accepted(option, key, pattern):
    with pytest.raises(SceneError) as info:
        load_rig_scene("dxl-arm", [option])
    err = info.value
    assert err.path == "--device" and err.key == key, str(err)
    assert re.search(pattern, err.problem), err.problem


def test_a_rig_file_applies_first_then_device_options(tmp_path):
    rig = tmp_path / "cell.toml"
    rig.write_text('[ft]\naddress = "/dev/ttyUSB0"\nbaudrate = 19200\n[arm]\naddress = "/dev/ttyUSB1"\n'
                   "ids = [1, 2, 3, 4, 5]\n")
    scene = load_rig_scene("dxl-arm", ["arm.address=/dev/ttyUSB2"], rig)
    assert _device(scene, "ft").address == "/dev/ttyUSB0"
    assert _device(scene, "arm").address == "/dev/ttyUSB2" and _device(scene, "arm").params["ids"] == [1, 2, 3, 4, 5]


@pytest.mark.parametrize(("text", "key", "pattern"), [
    ('[ft]\nbaud_rate = 19200\n', "ft.baud_rate", "did you mean 'baudrate'"),
    ("[ft]\nbaudrate = \"19200\"\n", "ft.baudrate", r"expected an integer.*got '19200'"),
    ('[ft]\naddress = 5\n', "ft.address", "expected a string, got 5"),
    ('[fx]\naddress = "/dev/ttyUSB0"\n', "fx", "scene 'dxl-arm' has no device 'fx'"),
    ('ft = "/dev/ttyUSB0"\n', "ft", r"expected a table \[ft\]"),
    ("[ft\n", "", "invalid TOML"),
])
def test_bad_rig_files_name_the_file_device_and_key(tmp_path, text, key, pattern):
    rig = tmp_path / "cell.toml"
    rig.write_text(text)
    with pytest.raises(SceneError) as info:
        load_rig_scene("dxl-arm", [], rig)
    assert info.value.path == str(rig) and info.value.key == key, str(info.value)
    assert re.search(pattern, info.value.problem), info.value.problem
