"""The scene's sensing (issue 37): what it has, what the pipeline uses, and the errors of both."""
from __future__ import annotations

import re

import numpy as np
import pytest

from ftc_hw.scene import SENSING_KINDS, SceneError, load_scene
from ftc_hw.scene.loader import builtin_dir


def _scene_text(edit) -> str:
    return edit((builtin_dir() / "leng2016.toml").read_text())


def _load(tmp_path, edit):
    (tmp_path / "leng2016.xml").write_text((builtin_dir() / "leng2016.xml").read_text())
    path = tmp_path / "scene.toml"
    path.write_text(_scene_text(edit))
    return load_scene(path)


def _without_sensor(text: str) -> str:
    """The scene with its [sensor] table and no torque constants taken out."""
    return re.sub(r"\n\[sensor\]\n(?:(?!\n\[).)*", "\n", text, flags=re.S)


def test_builtins_have_an_f_t_sensor_under_the_base_and_currents():
    for name in ("ur5e", "dxl-arm", "leng2016"):
        scene = load_scene(name)
        assert scene.sensor is not None and scene.sensor.mount == "base"
        assert scene.available.kinds == {"base_ft", "currents"}
        assert scene.sensing == scene.available


def test_a_scene_without_an_f_t_sensor_is_valid_and_says_so(tmp_path):
    scene = _load(tmp_path, _without_sensor)
    assert scene.sensor is None
    assert scene.sensing.kinds == {"currents"} and scene.sensing.ft is None and scene.sensing.currents
    with pytest.raises(SceneError, match="has no F/T sensor: the wizard needs one"):
        scene.require_ft("the wizard")


def test_joint_torque_sensors_and_uses(tmp_path):
    def edit(text):
        n = 3  # leng2016's joints
        return text + (f"\n[joint_torque]\nnoise_std = {[0.05] * n}\nrange = {[100.0] * n}\n"
                       f"offset = {[0.1] * n}\n\n[sensing]\nuses = [\"joint_torques\", \"base_ft\"]\n")
    scene = _load(tmp_path, edit)
    assert scene.available.kinds == {"base_ft", "joint_torques", "currents"}
    assert scene.sensing.kinds == {"base_ft", "joint_torques"}
    assert scene.sensing.label() == "base_ft + joint_torques"
    np.testing.assert_array_equal(scene.joint_torque.offset, [0.1] * 3)
    assert scene.joint_torque.rate_hz == 1000.0


def test_with_sensing_narrows_and_names_what_is_missing():
    scene = load_scene("ur5e")
    assert scene.with_sensing(["currents"]).sensing.kinds == {"currents"}
    assert scene.with_sensing(["currents"]).sensor is scene.sensor  # the hardware stays
    with pytest.raises(SceneError, match="has no flange_ft, joint_torques"):
        scene.with_sensing(["flange_ft", "joint_torques"])
    with pytest.raises(SceneError, match="unknown sensing 'imu'"):
        scene.with_sensing(["imu"])
    with pytest.raises(SceneError, match="at least one"):
        scene.with_sensing([])


@pytest.mark.parametrize(("edit", "key", "pattern"), [
    (lambda t: t.replace('[sensor]\n', '[sensor]\nmount = "wrist"\n'), "sensor.mount", "one of base, flange"),
    (lambda t: t + '\n[sensing]\nuses = ["flange_ft"]\n', "sensing.uses", "has no flange_ft"),
    (lambda t: t + '\n[sensing]\nuses = ["currents", "currents"]\n', "sensing.uses", "distinct"),
    (lambda t: t + '\n[sensing]\nwhat = 1\n', "sensing.what", "unknown key"),
    (lambda t: t + '\n[joint_torque]\nnoise_std = [0.1]\nrange = [1.0]\n', "joint_torque.noise_std", "3"),
    (lambda t: re.sub(r"torque_constant = \[[^\]]*\]\s*#[^\n]*\n", "", _without_sensor(t)), "sensor",
     "senses nothing"),
])
def test_malformed_sensing(tmp_path, edit, key, pattern):
    with pytest.raises(SceneError) as info:
        _load(tmp_path, edit)
    assert info.value.key == key, str(info.value)
    assert re.search(pattern, info.value.problem), info.value.problem


def test_the_sensing_kinds_are_documented():
    text = (builtin_dir().parents[2] / "docs" / "scenes.md").read_text()
    for kind in SENSING_KINDS:
        assert f"`{kind}`" in text, kind
