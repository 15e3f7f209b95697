"""The built-in UR e-Series scenes (ur3e, ur10e, ur16e) against Universal Robots' published numbers.

The tables below are typed from the sources, not read from the model files: UR's "DH Parameters for
calculations of kinematics and dynamics" (kinematics, link masses), the e-Series technical specifications
(arm weight, joint ranges) and UniversalRobots/Universal_Robots_ROS2_Description config/<arm>/
joint_limits.yaml (torques, speeds). The MJCF is read with MuJoCo directly, the TOML with tomllib, so these
run whatever the scene loader accepts; the last tests go through the loader (scene sensing schema).
"""
from __future__ import annotations

import tomllib

import mujoco
import numpy as np
import pytest

from ftc_hw.scene.loader import builtin_dir

ALPHA = (np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0)
# name: (d (m), a (m), link masses (kg), arm weight (kg), torque limits (N m), speed limits (deg/s))
UR = {
    "ur3e": ((0.15185, 0, 0, 0.13105, 0.08535, 0.0921), (0, -0.24355, -0.2132, 0, 0, 0),
             (1.98, 3.4445, 1.437, 0.871, 0.805, 0.261), 11.2, (54, 54, 28, 9, 9, 9), (180, 180, 180, 360, 360, 360)),
    "ur10e": ((0.1807, 0, 0, 0.17415, 0.11985, 0.11655), (0, -0.6127, -0.57155, 0, 0, 0),
              (7.369, 13.051, 3.989, 2.1, 1.98, 0.615), 33.5, (330, 330, 150, 54, 54, 54),
              (120, 120, 180, 180, 180, 180)),
    "ur16e": ((0.1807, 0, 0, 0.17415, 0.11985, 0.11655), (0, -0.4784, -0.36, 0, 0, 0),
              (7.369, 10.45, 4.321, 2.18, 2.033, 0.907), 33.1, (330, 330, 150, 54, 54, 54),
              (120, 120, 180, 180, 180, 180)),
}
LINKS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")


def _model(name: str) -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_path(str(builtin_dir() / f"{name}.xml"))


def _toml(name: str) -> dict:
    return tomllib.loads((builtin_dir() / f"{name}.toml").read_text())


def _dh_frames(q: np.ndarray, d, a) -> list[np.ndarray]:
    """UR's standard DH chain: T_i = T_{i-1} Rz(q_i) Tz(d_i) Tx(a_i) Rx(alpha_i), 4x4 each."""
    out, t = [], np.eye(4)
    for qi, di, ai, al in zip(q, d, a, ALPHA, strict=True):
        c, s, ca, sa = np.cos(qi), np.sin(qi), np.cos(al), np.sin(al)
        t = t @ np.array([[c, -s * ca, s * sa, ai * c], [s, c * ca, -c * sa, ai * s], [0, sa, ca, di], [0, 0, 0, 1]])
        out.append(t)
    return out


@pytest.mark.parametrize("name", sorted(UR))
def test_forward_kinematics_is_urs_dh_chain(name):
    d, a = UR[name][:2]
    m = _model(name)
    data = mujoco.MjData(m)
    rng = np.random.default_rng(7)
    configs = [np.zeros(6), np.array(_toml(name)["robot"]["home"])] + [rng.uniform(-np.pi, np.pi, 6) for _ in range(8)]
    worst = 0.0
    for q in configs:
        data.qpos[:] = q
        mujoco.mj_kinematics(m, data)
        for link, t in zip(LINKS, _dh_frames(q, d, a), strict=True):
            b = m.body(link).id
            worst = max(worst, np.linalg.norm(data.xpos[b] - t[:3, 3]))
            assert np.allclose(data.xmat[b].reshape(3, 3), t[:3, :3], atol=1e-9), (name, link, q)
        flange = m.site("flange").id
        assert np.linalg.norm(data.site_xpos[flange] - t[:3, 3]) < 5e-4
        assert np.allclose(data.site_xmat[flange].reshape(3, 3), t[:3, :3], atol=1e-9)
    assert worst < 5e-4, f"{name}: a link frame {worst * 1e3:.3f} mm off UR's DH chain"


@pytest.mark.parametrize("name", sorted(UR))
def test_masses_are_urs(name):
    link_masses, weight = UR[name][2], UR[name][3]
    m = _model(name)
    assert [m.body(link).mass[0] for link in LINKS] == pytest.approx(link_masses, abs=1e-9)
    # the base's mass is the published weight less the links' (SOURCES.md): the sum is the arm's weight
    tool = m.body("tool").mass[0] if "tool" in [m.body(i).name for i in range(m.nbody)] else 0.0
    assert m.body_mass.sum() - tool == pytest.approx(weight, abs=0.05)
    assert m.body("base").mass[0] > 0.5  # a real base housing, not a rounding remainder


@pytest.mark.parametrize("name", sorted(UR))
def test_joint_limits_are_urs(name):
    torques, speeds = UR[name][4], UR[name][5]
    m = _model(name)
    joints = _toml(name)["robot"]["joints"]
    for i, j in enumerate(joints):
        jid = m.joint(j).id
        if name == "ur3e" and j == "wrist_3_joint":  # the UR3e's end joint turns without limit
            assert not m.jnt_limited[jid]
        else:
            assert m.jnt_limited[jid] and m.jnt_range[jid] == pytest.approx([-2 * np.pi, 2 * np.pi])
        assert m.jnt_actfrclimited[jid] and m.jnt_actfrcrange[jid] == pytest.approx([-torques[i], torques[i]])
    assert m.numeric("max_joint_speed").data == pytest.approx(np.radians(speeds), rel=1e-9)


@pytest.mark.parametrize("name", sorted(UR))
def test_touchable_links_have_surfaces_and_the_flange_sensor_its_site(name):
    m = _model(name)
    scene = _toml(name)
    for t in scene["touchable"]:
        b = m.body(t["link"]).id
        assert sum(1 for g in range(m.ngeom) if m.geom_bodyid[g] == b and m.geom_group[g] == 1) >= 1, t["link"]
    site = m.site(scene["sensor"]["site"])
    assert scene["sensor"]["mount"] == "flange"
    # between wrist 3 and what is mounted on it: on the tool's body (ur10e: it carries a tool) or on wrist 3
    body = m.body(site.bodyid[0])
    assert body.name == "wrist_3" or (body.name == "tool" and m.body(body.parentid[0]).name == "wrist_3"
                                      and m.body_jntnum[body.id] == 0)
    assert site.bodyid[0] == m.site("flange").bodyid[0]
    assert np.allclose(site.pos, m.site("flange").pos) and np.allclose(site.quat, m.site("flange").quat)
    assert scene["sensor"]["rate_hz"] == 500.0 and [d["kind"] for d in scene["devices"]] == ["ur-rtde"]


@pytest.mark.parametrize("name", sorted(UR))
def test_home_is_away_from_singularities(name):
    m = _model(name)
    data = mujoco.MjData(m)
    data.qpos[:] = _toml(name)["robot"]["home"]
    mujoco.mj_forward(m, data)
    jp, jr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    mujoco.mj_jacSite(m, data, jp, jr, m.site("flange").id)
    assert np.linalg.svd(np.vstack([jp, jr]), compute_uv=False).min() > 0.1


def test_base_ft_variant_range_covers_the_ur10e_static_base_moment():
    """The UR10e stretched level with its 12.5 kg payload at the flange: the base moment stays inside the
    variant's torque range, and is above the smaller Omega160 calibration's 240 N m."""
    m = _model("ur10e")
    data = mujoco.MjData(m)
    mujoco.mj_forward(m, data)  # q = 0: the arm stretched level along -x
    g = 9.80665
    flange = data.site_xpos[m.site("flange").id]
    arm = sum(m.body_mass[b] * g * np.hypot(*data.xipos[b][:2]) for b in range(1, m.nbody))
    moment = arm + 12.5 * g * np.hypot(*flange[:2])
    variant = tomllib.loads((builtin_dir() / "variants" / "ur10e-base-ft.toml").read_text())
    tx_range = variant["sensor"]["range"][3]
    assert 240.0 < moment < tx_range
    assert variant["sensor"]["mount"] == "base" and variant["sensing"]["uses"] == ["base_ft", "currents"]
    assert m.site(variant["sensor"]["site"]).bodyid[0] == m.body("base").id


# Through the scene loader: these need the scene sensing schema ([sensor] mount, [sensing]).

@pytest.mark.parametrize("name", sorted(UR))
def test_the_loader_reads_the_ur_scenes_sensing(name):
    from ftc_hw.model import ArmModel
    from ftc_hw.scene import load_scene

    scene = load_scene(name)
    assert scene.sensor is not None and scene.sensor.mount == "flange"
    assert scene.sensing.kinds == {"currents", "flange_ft"}
    assert scene.sensing.ft == "flange" and scene.sensing.currents and not scene.sensing.joint_torques
    assert ArmModel(scene).n_joints == 6
    assert np.allclose(scene.robot.torque_constant, _toml(name)["robot"]["torque_constant"])


def test_the_loader_reads_the_base_ft_variant():
    from ftc_hw.scene import load_scene

    scene = load_scene("ur10e-base-ft")
    assert scene.sensor.mount == "base" and scene.sensing.ft == "base" and scene.sensing.currents
    assert [d.kind for d in scene.devices] == ["ft-can", "ur-rtde"]
    assert scene.robot.model_path == load_scene("ur10e").robot.model_path
