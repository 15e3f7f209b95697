"""Scene files: built-ins load; every malformed file gets an error naming the file, the key and the problem."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from ftc_hw.model import ArmModel
from ftc_hw.scene import SceneError, builtin_names, load_scene, variant_names
from ftc_hw.scene.device_params import KINDS
from ftc_hw.scene.loader import builtin_dir

LENG = (builtin_dir() / "leng2016.toml").read_text()


def test_builtins_present_and_load():
    assert {"leng2016", "ur5e", "dxl-arm"} <= set(builtin_names())
    for name in builtin_names():
        scene = load_scene(name)
        assert scene.name == name
        assert scene.robot.model_path.is_file()
        model = ArmModel(scene)
        assert model.n_joints == scene.n_joints
        assert model.surfaces, name


def test_user_scene_is_a_path(tmp_path):
    p = _write(tmp_path, LENG.replace('name = "leng2016"', 'name = "mine"'))
    assert load_scene(p).name == "mine"
    assert load_scene(str(p)).name == "mine"


def _write(tmp_path: Path, text: str, name: str = "scene.toml", model: str = "leng2016") -> Path:
    # Copy the model beside the scene so relative paths resolve.
    (tmp_path / f"{model}.xml").write_text((builtin_dir() / f"{model}.xml").read_text())
    p = tmp_path / name
    p.write_text(text)
    return p


def _expect(tmp_path, text, key, pattern, model="leng2016"):
    p = _write(tmp_path, text, model=model)
    with pytest.raises(SceneError) as info:
        ArmModel(load_scene(p))
    err = info.value
    assert err.path == str(p)
    assert err.key == key, str(err)
    assert re.search(pattern, err.problem), err.problem
    assert str(p) in str(err) and key in str(err)


def test_unknown_builtin_and_missing_file(tmp_path):
    with pytest.raises(SceneError, match="no built-in scene"):
        load_scene("no-such-scene")
    with pytest.raises(SceneError, match="cannot read"):
        load_scene(tmp_path / "absent.toml")


def test_invalid_toml(tmp_path):
    _expect(tmp_path, LENG + "\n[robot\n", "", "invalid TOML")


def test_not_utf8(tmp_path):
    p = tmp_path / "s.toml"
    p.write_bytes(b"name = \"\xff\xfe\"\n")
    with pytest.raises(SceneError, match="UTF-8"):
        load_scene(p)


@pytest.mark.parametrize(("old", "new", "key", "pattern"), [
    ("schema = 1", "schema = 7", "schema", "schema version 1"),
    ("schema = 1", "", "schema", "missing key"),
    ('name = "leng2016"', "name = 3", "name", "expected a string, got int"),
    ("[gravity]\nvector = [0.0, -9.801, 0.0]", "[gravity]\nvector = [0.0, -9.801]", "gravity.vector",
     "3 numbers, got 2"),
    ("[gravity]\nvector = [0.0, -9.801, 0.0]", "[gravity]\nvector = [0.0, nan, 0.0]", "gravity.vector[1]", "finite"),
    ("[gravity]\nvector = [0.0, -9.801, 0.0]", "[gravity]\nvector = [0.0, \"x\", 0.0]", "gravity.vector[1]",
     "expected a number"),
    ('reports = "base_on_arm"', 'reports = "sideways"', "sensor.reports", "one of base_on_arm, arm_on_base"),
    ("rate_hz = 1000.0", "rate_hz = -5", "sensor.rate_hz", "positive"),
    ("rate_hz = 1000.0", "rate_hz = true", "sensor.rate_hz", "boolean"),
    ("noise_std = [0.05,", "noise_std = [-0.05,", "sensor.noise_std[0]", ">= 0"),
    ('level = "gravity"', 'level = "magic"', "compensation.level", "bias, gravity, dynamics"),
    ('site = "ft_sensor"', 'site = "ft_sensor"\ncolour = "red"', "sensor.colour", "unknown key"),
    ('model = "leng2016.xml"', 'model = "missing.xml"', "robot.model", "not found"),
    ('model = "leng2016.xml"', 'model = "leng2016.stl"', "robot.model", "MJCF"),
    ('joints = ["joint1", "joint2", "joint3"]', 'joints = ["joint1", "joint1", "joint3"]', "robot.joints", "unique"),
    ('joints = ["joint1", "joint2", "joint3"]', 'joints = ["joint1", "elbow", "joint3"]', "robot.joints",
     "no joint 'elbow'"),
    ('joints = ["joint1", "joint2", "joint3"]', 'joints = ["joint1", "joint2"]', "robot.home", "2 numbers, got 3"),
    ('site = "ft_sensor"', 'site = "nowhere"', "sensor.site", "no site 'nowhere'"),
    ('link = "link2"', 'link = "link9"', "touchable.link", "no body 'link9'"),
    ('link = "link2"', 'link = "world"', "touchable.link", "no surface geoms"),
    ('link = "link2"', 'link = "link1"', "touchable", "listed twice"),
    ('[[devices]]\nname = "ft"', '[[devices]]\nname = 5', "devices[0].name", "expected a string"),
    ('[compensation]\nlevel = "gravity"', "", "compensation", "missing table"),
    ("[compensation]", "[compensation_]", "compensation_", "unknown key"),
])
def test_malformed(tmp_path, old, new, key, pattern):
    assert old in LENG, old
    _expect(tmp_path, LENG.replace(old, new, 1), key, pattern)


def test_broken_model_file(tmp_path):
    p = _write(tmp_path, LENG)
    (tmp_path / "leng2016.xml").write_text("<mujoco><worldbody><body></mujoco>")
    with pytest.raises(SceneError) as info:
        ArmModel(load_scene(p))
    assert info.value.key == "robot.model" and "cannot load" in info.value.problem


def test_missing_touchable(tmp_path):
    text = re.sub(r"\[\[touchable\]\]\nlink = \"\w+\"\npulls = false[^\n]*\n", "", LENG)
    _expect(tmp_path, text, "touchable", "at least one")


DXL = (builtin_dir() / "dxl-arm.toml").read_text()
COUPLING = '''joint = "gripper"
drives = ["gripper_left_joint", "gripper_right_joint"]'''


@pytest.mark.parametrize(("old", "new", "key", "pattern"), [
    ('joint = "gripper"', 'joint = "jaw"', "robot.couplings[0].joint", "not one of robot.joints"),
    (COUPLING, 'joint = "gripper"\ndrives = ["gripper_left_joint", "gripper_left_joint"]', "robot.couplings[0].drives",
     "distinct"),
    (COUPLING, 'joint = "gripper"\ndrives = ["gripper_left_joint", "joint4"]', "robot.couplings[0].drives",
     "scene joint itself"),
    (COUPLING, 'joint = "gripper"\ndrives = ["gripper_left_joint", "thumb"]', "robot.couplings", "no joint 'thumb'"),
    ("ratios = [0.015, 0.015]", "ratios = [0.015, 0.0]", "robot.couplings[0].ratios", "drives nothing"),
    ("ratios = [0.015, 0.015]", "ratios = [0.015]", "robot.couplings[0].ratios", "2 numbers, got 1"),
    ("ratios = [0.015, 0.015]", "ratios = [0.015, 0.015]\ngear = 2", "robot.couplings[0].gear", "unknown key"),
])
def test_malformed_couplings(tmp_path, old, new, key, pattern):
    assert old in DXL, old
    _expect(tmp_path, DXL.replace(old, new, 1), key, pattern, model="dxl-arm")


def test_a_model_joint_the_scene_does_not_set_is_an_error(tmp_path):
    text = DXL.replace(COUPLING, 'joint = "gripper"\ndrives = ["gripper_left_joint"]', 1)
    _expect(tmp_path, text.replace("ratios = [0.015, 0.015]", "ratios = [0.015]", 1), "robot.joints",
            "6 position coordinates but the scene sets 5 .*gripper_left_joint", model="dxl-arm")


# -- device params: the schema per kind (ftc_hw.scene.device_params) ------------------------------------
@pytest.mark.parametrize(("old", "new", "key", "pattern"), [
    ("baudrate = 19200", "baud_rate = 19200", "devices[0].params.baud_rate",
     r"device 'ft': unknown parameter of device kind ft300 \(accepted: mode, device_id, baudrate, .*\); "
     r"did you mean 'baudrate'\?"),
    ("device_id = 9", 'device_id = "nine"', "devices[0].params.device_id", r"device 'ft': expected an integer.*'nine'"),
    ("device_id = 9", "device_id = 300", "devices[0].params.device_id", r"<= 247, got 300 \(out of range\)"),
    ('mode = "stream"', 'mode = "burst"', "devices[0].params.mode", "one of stream, poll, got 'burst'"),
    ("baudrate = 1000000", "baudrate = 1000001", "devices[1].params.baudrate", "one of 9600, 57600"),
    ("ids = [11, 12, 13, 14, 15]", "ids = [11, 12, 13, 14, 300]", "devices[1].params.ids", "out of range"),
    ("directions = [1, 1, 1, 1, -1]", "directions = [1, 1, 1, 1, 0]", "devices[1].params.directions",
     "a list, each one of -1, 1"),
    ('kind = "dynamixel"', 'kind = "dynamixl"', "devices[1].kind", "did you mean 'dynamixel'"),
    ('kind = "ft300"\ntransport = "modbus-rtu"', 'kind = "ft300"\ntransport = "serial"', "devices[0].transport",
     "transport modbus-rtu, modbus-tcp, not 'serial'"),
    ('kind = "ft300"\ntransport = "modbus-rtu"\n[devices.params]\nbaudrate = 19200\ndevice_id = 9\nmode = "stream"',
     'kind = "modbus-ft"\ntransport = "modbus-rtu"\n[devices.params]\nbaudrate = 19200\ndevice_id = 9',
     "devices[0].params.map", "required by device kind modbus-ft"),
])
def test_device_params_are_checked_against_their_kind(tmp_path, old, new, key, pattern):
    assert old in DXL, old
    _expect(tmp_path, DXL.replace(old, new, 1), key, pattern, model="dxl-arm")


def test_builtin_scenes_name_no_hardware_address():
    for name in builtin_names():
        assert all(d.address is None for d in load_scene(name).devices), name


def test_the_hardware_page_lists_every_param_of_every_kind():
    page = (Path(__file__).resolve().parents[2] / "docs" / "hardware.md").read_text()
    tables = page.split("## Params of each kind", 1)[1].split("\n### `")[1:]
    assert [t.split("`", 1)[0] for t in tables] == list(KINDS)
    for text, kind in zip(tables, KINDS.values(), strict=True):
        rows = [line.split("`")[1] for line in text.splitlines() if line.startswith("| `")]
        assert rows == list(kind.names), kind.kind


def test_a_scene_error_crosses_a_process_boundary_whole():
    """A bench's worker process raises it; the parent gets the same file, key and problem."""
    import pickle

    err = pickle.loads(pickle.dumps(SceneError("/x/ur5e.toml", "world.model", "no joint 'elbow'")))
    assert (err.path, err.key, err.problem) == ("/x/ur5e.toml", "world.model", "no joint 'elbow'")
    assert str(err) == "/x/ur5e.toml: world.model: no joint 'elbow'"


def test_variants_extend_a_builtin_and_load_by_name():
    assert "ur5e-netft" in variant_names() and "ur5e-netft" not in builtin_names()
    base, netft = load_scene("ur5e"), load_scene("ur5e-netft")
    assert netft.name == "ur5e-netft" and netft.sensor.rate_hz == 7000.0
    assert np.array_equal(netft.sensor.range, base.sensor.range) and netft.robot.joints == base.robot.joints
    assert [d.kind for d in netft.devices] == ["ft-rdt", "ur-rtde"]  # arrays of tables replace, not merge
    model = ArmModel(netft)
    assert model.n_joints == 6 and abs(1.0 / 7000.0 - float(model.model.opt.timestep)) < 1e-12


def test_extends_errors_name_the_file_and_key(tmp_path):
    (tmp_path / "a.toml").write_text('extends = "b.toml"\n')
    (tmp_path / "b.toml").write_text('extends = "a.toml"\n')
    with pytest.raises(SceneError, match="extends.*cycle"):
        load_scene(tmp_path / "a.toml")
    (tmp_path / "c.toml").write_text('extends = "nowhere.toml"\n')
    with pytest.raises(SceneError, match="extends.*no built-in scene 'nowhere.toml'"):
        load_scene(tmp_path / "c.toml")
    (tmp_path / "d.toml").write_text(LENG.replace('schema = 1', 'extends = "leng2016"\nschema = 1')
                                     .replace('name = "leng2016"', 'name = "mine"'))
    (tmp_path / "leng2016.xml").write_text((builtin_dir() / "leng2016.xml").read_text())
    assert load_scene(tmp_path / "d.toml").name == "mine"
