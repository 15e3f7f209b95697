"""The built-in Franka scenes (``panda``, ``fr3``) against their published sources: Franka's modified-DH
kinematics, joint limits and torque limits; the cited dynamic models' masses and gravity torques.

The scene files' ``[joint_torque]`` and ``[sensing]`` tables are read with tomllib here, and the models
with MuJoCo directly, so that these checks do not depend on the scene loader."""
from __future__ import annotations

import math
import tomllib

import mujoco
import numpy as np
import pytest

from ftc_hw.scene.loader import builtin_dir

# Franka, "Robot and interface specifications": (a, d, alpha) of joints 1-7 and the flange (Craig's
# convention, the same table for the Panda and the FR3)
DH = [(0.0, 0.333, 0.0), (0.0, 0.0, -math.pi / 2), (0.0, 0.316, math.pi / 2), (0.0825, 0.0, math.pi / 2),
      (-0.0825, 0.384, -math.pi / 2), (0.0, 0.0, math.pi / 2), (0.088, 0.0, math.pi / 2), (0.0, 0.107, 0.0)]
LIMITS = {  # (q_min, q_max) rad, same source: the Panda's table and the FR3's
    "panda": ([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973],
              [2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973]),
    "fr3": ([-2.9007, -1.8361, -2.9007, -3.0770, -2.8763, 0.4398, -3.0508],
            [2.9007, 1.8361, 2.9007, -0.1169, 2.8763, 4.6216, 3.0508]),
}
TAU_MAX = [87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0]  # N m, tau_j_max of both arms
MASSES = {  # kg, links 1-7
    # Gaz et al., RA-L 2019, supplementary material Table VIII (p-hat)
    "panda": [4.970684, 0.646926, 3.228604, 3.587895, 1.225946, 1.666555, 0.735522],
    # frankaemika/franka_description robots/fr3/inertials.yaml
    "fr3": [2.9274653454, 2.9355370338, 2.2449013699, 2.6155955791, 2.3271207594, 1.8170376524, 0.6271432862],
}
HOME = [0.0, -math.pi / 4, 0.0, -3 * math.pi / 4, 0.0, math.pi / 2, math.pi / 4]
# g(q) at HOME, N m: marcocognetti/FrankaEmikaPandaDynModel matlab/dyn_model_panda/get_GravityVector.m
# (Gaz et al.'s identified gravity vector, g0 = 9.80665) evaluated at HOME
GAZ_GRAVITY_HOME = [0.0, -1.738757, -0.668258, 18.52398, 0.715814, 1.671368, 0.0]


def dh_chain(q) -> list[np.ndarray]:
    """Base-frame poses (4x4) of link frames 1-7 and the flange, from Franka's table."""
    out, t = [], np.eye(4)
    for i, (a, d, alpha) in enumerate(DH):
        th = q[i] if i < 7 else 0.0
        ca, sa, ct, st = math.cos(alpha), math.sin(alpha), math.cos(th), math.sin(th)
        t = t @ np.array([[ct, -st, 0.0, a], [st * ca, ct * ca, -sa, -sa * d], [st * sa, ct * sa, ca, ca * d],
                          [0.0, 0.0, 0.0, 1.0]])
        out.append(t)
    return out


def scene_file(name: str) -> dict:
    with open(builtin_dir() / f"{name}.toml", "rb") as f:
        return tomllib.load(f)


def arm(name: str) -> tuple[mujoco.MjModel, mujoco.MjData, dict]:
    toml = scene_file(name)
    m = mujoco.MjModel.from_xml_path(str(builtin_dir() / toml["robot"]["model"]))
    return m, mujoco.MjData(m), toml


def set_q(m: mujoco.MjModel, d: mujoco.MjData, joints: list[str], q) -> None:
    for j, v in zip(joints, q, strict=True):
        d.qpos[m.jnt_qposadr[m.joint(j).id]] = v


@pytest.mark.parametrize("name", ["panda", "fr3"])
def test_forward_kinematics_is_frankas_dh(name):
    m, d, toml = arm(name)
    joints = toml["robot"]["joints"]
    lo, hi = LIMITS[name]
    configs = [HOME, [0.0] * 7] + list(np.random.default_rng(3).uniform(lo, hi, (4, 7)))
    configs[1][3] = -1.0  # joint 4 has no zero in its range
    for q in configs:
        set_q(m, d, joints, q)
        mujoco.mj_kinematics(m, d)
        chain = dh_chain(q)
        for i in range(7):
            assert np.linalg.norm(d.xpos[m.body(f"link{i + 1}").id] - chain[i][:3, 3]) < 5e-4
        flange = m.site(toml["robot"]["flange"]).id
        assert np.linalg.norm(d.site_xpos[flange] - chain[7][:3, 3]) < 5e-4
        assert np.allclose(d.site_xmat[flange].reshape(3, 3), chain[7][:3, :3], atol=1e-6)


@pytest.mark.parametrize("name", ["panda", "fr3"])
def test_masses_and_limits_are_the_cited_ones(name):
    m, _, toml = arm(name)
    masses = [m.body_mass[m.body(f"link{i}").id] for i in range(1, 8)]
    assert np.allclose(masses, MASSES[name], rtol=0, atol=1e-9)
    ranges = np.array([m.jnt_range[m.joint(j).id] for j in toml["robot"]["joints"]])
    assert np.array_equal(ranges[:, 0], LIMITS[name][0]) and np.array_equal(ranges[:, 1], LIMITS[name][1])
    assert all(m.jnt_limited[m.joint(j).id] for j in toml["robot"]["joints"])
    assert np.all((ranges[:, 0] < toml["robot"]["home"]) & (toml["robot"]["home"] < ranges[:, 1]))
    sensing = toml["joint_torque"]
    assert sensing["range"] == TAU_MAX and toml["sensing"]["uses"] == ["joint_torques"]
    assert len(sensing["noise_std"]) == len(sensing["offset"]) == 7 and "sensor" not in toml
    assert "torque_constant" not in toml["robot"]  # libfranka reports no motor currents
    assert {t["link"] for t in toml["touchable"]} == {f"link{i}" for i in range(1, 8)}


def test_panda_gravity_at_home_is_gaz_model():
    """The MJCF holds Gaz et al.'s retrieved parameters; their published gravity vector comes from the
    identified dynamic coefficients, which those parameters reproduce to a few hundredths of N m."""
    m, d, toml = arm("panda")
    set_q(m, d, toml["robot"]["joints"], HOME)
    mujoco.mj_forward(m, d)
    assert np.abs(d.qfrc_bias - GAZ_GRAVITY_HOME).max() < 0.15
    assert abs(d.qfrc_bias[3]) > 18.0  # not trivially small: the elbow carries the forearm


def test_fr3_gravity_at_home_is_near_the_panda_model():
    """Franka's FR3 inertials against the Panda's identified model: the same kinematics and joint modules,
    so the gravity torques at home agree to within a few per cent of joint 4's."""
    m, d, toml = arm("fr3")
    set_q(m, d, toml["robot"]["joints"], HOME)
    mujoco.mj_forward(m, d)
    assert np.abs(d.qfrc_bias - GAZ_GRAVITY_HOME).max() < 0.6
