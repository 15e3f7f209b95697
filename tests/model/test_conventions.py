"""docs/conventions.md, checked: wrench order, what each sign convention reports, frames, quaternions."""
from __future__ import annotations

import numpy as np
import pytest

from ftc_hw.model import ArmModel, Contact
from ftc_hw.scene import load_scene
from ftc_hw.solver import ContactSolver


def test_wrench_is_force_then_torque_in_n_and_nm():
    """A pure force along +x applied at +z on the sensor axis gives a torque about y, in slots 3..5."""
    model = ArmModel(load_scene("leng2016"))
    q = np.zeros(3)
    c, p = np.array([0.0, 0.0, 0.2]), np.array([10.0, 0.0, 0.0])
    w = model.predicted_wrench(q, level="bias", contacts=[Contact("link1", c, p)])
    np.testing.assert_allclose(w[:3], [-10.0, 0.0, 0.0], atol=1e-12)  # base_on_arm: -p
    np.testing.assert_allclose(w[3:], [0.0, -2.0, 0.0], atol=1e-12)  # -(c x p) = -(0, 2, 0) N m


@pytest.mark.parametrize("reports,sign", [("base_on_arm", -1.0), ("arm_on_base", 1.0)])
def test_sign_conventions(tmp_path, reports, sign, custom_scene):
    scene = custom_scene(tmp_path, "conv", "capsule", "0.05 0.2", "sphere", "0.06", reports=reports)
    model = ArmModel(scene)
    q = np.array(scene.robot.home)
    rest = model.predicted_wrench(q, level="gravity")
    mass = model.total_mass
    # at rest: base_on_arm reads +m g up (gravity -z), arm_on_base reads the weight pushing down
    np.testing.assert_allclose(rest[:3], [0.0, 0.0, -sign * mass * 9.81], atol=1e-9)
    c = model.kinematics(q)["l1"][:3, 3] + np.array([0.05, 0.0, 0.2])
    p = np.array([-5.0, 3.0, 1.0])
    delta = model.predicted_wrench(q, level="gravity", contacts=[Contact("l1", c, p)]) - rest
    np.testing.assert_allclose(delta, sign * np.concatenate([p, np.cross(c, p)]), atol=1e-9)
    # the solver reads either convention back to the same contact
    e = ContactSolver(scene).solve(delta, q)
    np.testing.assert_allclose(e.point, c, atol=1e-9)
    np.testing.assert_allclose(e.force, p, atol=1e-9)


def test_sensor_frame_offset_and_rotation(tmp_path):
    """A wrench in the sensor frame about the sensor origin re-expressed in base about the base origin."""
    scene = load_scene("leng2016")
    model = ArmModel(scene)
    q = np.array(scene.robot.home)
    np.testing.assert_allclose(model.base_T_sensor(q), np.eye(4), atol=1e-15)  # leng2016: base = sensor
    w = np.array([1.0, 2.0, 3.0, 0.1, 0.2, 0.3])
    np.testing.assert_allclose(model.wrench_sensor_to_base(q, w), w, atol=1e-15)


def test_poses_are_base_T_frame_and_quaternions_scalar_first():
    model = ArmModel(load_scene("leng2016"))
    q = np.array([np.pi / 2, 0.0, 0.0])
    base_T_link1 = model.kinematics(q)["link1"]
    # link1 turned +90 deg about z: its x axis is the base y axis, maps link points into base
    np.testing.assert_allclose(base_T_link1[:3, 0], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(base_T_link1 @ [1.0, 0, 0, 1], [0, 1, 0.12, 1], atol=1e-12)
    m, d = model.model, model.data
    quat = d.xquat[m.body("link1").id]
    np.testing.assert_allclose(quat, [np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)], atol=1e-12)  # w, x, y, z
