"""The world as another arm: each ``[world]`` difference acts in the world on its own, the reality draws
are seeded and within their tolerances, and a bad ``[world]`` table or true model is a SceneError."""
from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np
import pytest

from ftc_hw.model import ArmModel
from ftc_hw.scene import SceneError, builtin_names, load_scene
from ftc_hw.scene.loader import builtin_dir
from ftc_hw.scene.world_spec import InertialError, WorldSpec
from ftc_hw.sim_devices.world import (
    DIFFERENCES,
    Hold,
    Probe,
    Reality,
    ScenarioSetup,
    Sinusoid,
    World,
    with_reality,
)
from ftc_hw.sim_devices.world.reality import TOLERANCES

pytestmark = pytest.mark.compute  # computes only (nothing timed): runs with the others on every core

UR5E = load_scene("ur5e")
HOME = np.array(UR5E.robot.home)


def _true(scene, **world):
    return dataclasses.replace(scene, world=dataclasses.replace(scene.world, **world))


def _still_reading(scene, seconds=0.3, noise=False, seed=0):
    world = World(scene, ScenarioSetup(Hold(HOME)), seed=seed, noise=noise)
    readings = [r.wrench for _, r in world.run(seconds)]
    return np.array(readings), world


def test_ideal_is_the_model_and_draws_are_seeded():
    assert with_reality(UR5E, "ideal", seed=5) is UR5E
    a, b = with_reality(UR5E, "typical", seed=5), with_reality(UR5E, "typical", seed=5)
    assert a.world.inertials.keys() == b.world.inertials.keys()
    np.testing.assert_array_equal(a.world.sensor_gain, b.world.sensor_gain)
    c = with_reality(UR5E, "typical", seed=6)
    assert not np.array_equal(a.world.sensor_gain, c.world.sensor_gain)
    # one difference on its own keeps the values it has in the full draw; the rest stay ideal
    only = with_reality(UR5E, "typical", seed=5, only=("gain",))
    np.testing.assert_array_equal(only.world.sensor_gain, a.world.sensor_gain)
    assert not only.world.inertials and only.world.friction_coulomb is None
    with pytest.raises(ValueError, match="unknown differences"):
        with_reality(UR5E, "typical", only=("nope",))


@pytest.mark.parametrize("reality", [Reality.TYPICAL, Reality.HARSH])
def test_draws_stay_within_their_tolerances(reality):
    tol = TOLERANCES[reality]
    for seed in range(5):
        w = with_reality(UR5E, reality, seed=seed).world
        assert len(w.inertials) == 6  # the six moving links of the UR5e
        for e in w.inertials.values():
            assert abs(e.mass_scale - 1) <= tol.mass_rel and abs(e.inertia_scale - 1) <= tol.inertia_rel
            assert np.all(np.abs(e.com_offset) <= tol.com_m)
        assert np.all(np.abs(w.sensor_offset) <= tol.mount_m) and np.all(np.abs(w.sensor_rotation) <= tol.mount_rad)
        assert np.all(np.abs(w.torque_constant / UR5E.robot.torque_constant - 1) <= tol.torque_constant_rel)
        # the vendor's meshes are the shell (scripts/bootstrap.sh fetches them): no drawn offsets
        assert w.vendor_shell == "robosuite-ur5e" and not w.shell_offsets
        assert not w.is_ideal
        dxl = with_reality(load_scene("dxl-arm"), reality, seed=seed).world  # no vendor meshes: offsets
        assert dxl.vendor_shell is None and len(dxl.shell_offsets) >= 5
        assert all(0.5 * tol.shell_m <= v <= tol.shell_m for v in dxl.shell_offsets.values())


def test_inertials_change_the_static_reading():
    base, _ = _still_reading(UR5E)
    heavier, _ = _still_reading(_true(UR5E, inertials={"upper_arm": InertialError(mass_scale=1.05)}))
    # ur5e reports the arm's load on the base: 5 % more upper arm (8.058 kg) is 0.403 kg more weight
    dfz = float(np.mean(heavier[:, 2] - base[:, 2]))
    assert dfz == pytest.approx(-0.05 * 8.058 * 9.80665, rel=0.01)
    moved, _ = _still_reading(_true(UR5E, inertials={"forearm": InertialError(com_offset=np.array([0.0, 0.0, 0.01]))}))
    assert np.max(np.abs(np.mean(moved - base, axis=0)[3:])) > 0.1  # 2.846 kg x 1 cm: a 0.28 N m lever at most


def test_sensor_mount_rotation_and_gain_act_on_the_reading():
    base, _ = _still_reading(UR5E)
    tilted, _ = _still_reading(_true(UR5E, sensor_rotation=np.array([math.radians(1.0), 0.0, 0.0])))
    # rotating the sensor frame 1 degree about x moves about fz sin(1 deg) of the weight into fy
    fz = float(np.mean(base[:, 2] - UR5E.sensor.bias[2]))
    assert float(np.mean(tilted[:, 1] - base[:, 1])) == pytest.approx(fz * math.sin(math.radians(1.0)), rel=0.05)
    gain = np.eye(6)
    gain[0, 2] = 0.01  # 1 % crosstalk of fz into fx
    crossed, _ = _still_reading(_true(UR5E, sensor_gain=gain))
    assert float(np.mean(crossed[:, 0] - base[:, 0])) == pytest.approx(0.01 * fz, rel=0.01)


def test_coloured_noise_is_correlated_and_thermal_drift_grows():
    std = np.array([0.5, 0, 0, 0, 0, 0])
    coloured, _ = _still_reading(_true(UR5E, coloured_noise_std=std, coloured_noise_tau_s=0.5), seconds=2.0,
                                 noise=True)
    white, _ = _still_reading(UR5E, seconds=2.0, noise=True)

    def lag_corr(x):
        x = x - x.mean()
        return float(np.dot(x[:-10], x[10:]) / np.dot(x, x))

    assert lag_corr(coloured[:, 0]) > 0.5 > abs(lag_corr(white[:, 0])) + 0.4
    warm = _true(UR5E, temperature_drift=np.array([0, 0, 0.2, 0, 0, 0]), temperature_rise_K=5.0,
                 temperature_tau_s=1.0)
    drifting, world = _still_reading(warm, seconds=2.0)
    steady, _ = _still_reading(UR5E, seconds=2.0)
    d = drifting[:, 2] - steady[:, 2]
    assert d[-1] == pytest.approx(0.2 * 5.0 * (1 - math.exp(-world.t / 1.0)), abs=2e-3)
    assert abs(d[0]) < 0.01


def _sweep_currents(scene, seconds=1.5):
    world = World(scene, ScenarioSetup(Sinusoid(HOME, np.array([0.6, 0, 0, 0, 0, 0]), 0.5, start_s=0.0)), noise=False)
    rows = [(s.qd[0], world.read_current(s)[0]) for s, _ in world.run(seconds)]
    return np.array(rows)


def test_friction_and_torque_constant_show_in_the_motor_current():
    base = _sweep_currents(UR5E)
    rough = _sweep_currents(_true(UR5E, friction_coulomb=UR5E.robot.friction_coulomb * 2.0))
    moving = np.abs(base[:, 0]) > 0.2
    # the base joint turns about a vertical axis: its current is friction and inertia; doubling its
    # Coulomb friction (4 N m at 13 N m/A) adds about 0.31 A against the motion
    extra = np.mean(np.sign(base[moving, 0]) * (rough[moving, 1] - base[moving, 1]))
    assert extra == pytest.approx(4.0 / 13.0, rel=0.15)
    stiff = _sweep_currents(_true(UR5E, friction_stribeck=np.array([4.0, 0, 0, 0, 0, 0]), stribeck_velocity=0.05))
    slow = (np.abs(base[:, 0]) > 0.01) & (np.abs(base[:, 0]) < 0.03)
    assert np.mean(np.sign(base[slow, 0]) * (stiff[slow, 1] - base[slow, 1])) > 0.1
    assert np.mean(np.abs(stiff[moving, 1] - base[moving, 1])) < 0.02  # gone at speed
    kt = UR5E.robot.torque_constant.copy()
    kt[0] *= 1.1
    weaker = _sweep_currents(_true(UR5E, torque_constant=kt))
    np.testing.assert_allclose(weaker[moving, 1], base[moving, 1] / 1.1, atol=0.01)


def test_shell_moves_the_touched_surface_out():
    scene = _true(UR5E, shell_offset=0.004)
    model = ArmModel(UR5E)
    surf = next(s for s in model.surfaces if s.link == "forearm")
    link_T = model.kinematics(HOME)["forearm"]
    # a point on the forearm tube's side: its radius out from the axis along the geom's x
    geom_T = link_T @ surf.link_T_geom
    point = geom_T[:3, 3] + surf.size[0] * geom_T[:3, 0]
    normal = geom_T[:3, 0]
    r = link_T[:3, :3]
    probe = Probe("forearm", r.T @ (point - link_T[:3, 3]), -normal, 20.0, 0.0, normal_link=r.T @ normal,
                  geom=surf.geom)
    world = World(scene, ScenarioSetup(Hold(HOME), probes=(probe,)), noise=False)
    world.start_script()
    truths = [c for s, _ in world.run(0.2) for c in s.contacts]
    assert truths
    # in the link's frame (the push deflects the arm a little): 4 mm out along the normal
    bid = world.model.body("forearm").id
    rot, pos = world.data.xmat[bid].reshape(3, 3), world.data.xpos[bid]
    np.testing.assert_allclose(rot.T @ (truths[-1].point - pos), probe.point_link + 0.004 * probe.normal_link,
                               atol=1e-5)


def _scene_with_world(tmp_path, world_toml: str, true_xml: str | None = None):
    (tmp_path / "ur5e.xml").write_text((builtin_dir() / "ur5e.xml").read_text())
    (tmp_path / "ati_netft_can.dbc").write_text((builtin_dir() / "ati_netft_can.dbc").read_text())
    if true_xml is not None:
        (tmp_path / "true.xml").write_text(true_xml)
    text = (builtin_dir() / "ur5e.toml").read_text().replace("[compensation]", world_toml + "\n[compensation]")
    p = tmp_path / "scene.toml"
    p.write_text(text)
    return p


@pytest.mark.parametrize(("world_toml", "key"), [
    ('[world]\nshell_offset_m = 0.2\n', "world.shell_offset_m"),
    ('[world]\nfriction_coulomb = [1, 2]\n', "world.friction_coulomb"),
    ('[world]\nsensor_gain = [[1, 0]]\n', "world.sensor_gain"),
    ('[world]\ntypo = 1\n', "world.typo"),
    ('[world.inertials.forearm]\nmass_scale = -1.0\n', "world.inertials.forearm.mass_scale"),
    ('[world]\nmodel = "absent.xml"\n', "world.model"),
])
def test_malformed_world_tables_name_the_key(tmp_path, world_toml, key):
    with pytest.raises(SceneError) as err:
        load_scene(_scene_with_world(tmp_path, world_toml))
    assert err.value.key == key and "scene.toml" in str(err.value)


@pytest.mark.parametrize(("edit", "world_toml", "pattern"), [
    (("wrist_3_joint", "wrist_3_jnt"), '[world]\nmodel = "true.xml"\n', "no joint 'wrist_3_joint'"),
    (('mass="3.761"', 'mass="-3.761"'), '[world]\nmodel = "true.xml"\n', "negative mass"),
    (None, '[world.inertials.nolink]\nmass_scale = 1.1\n', "no body 'nolink'"),
])
def test_inconsistent_true_model_is_a_scene_error_before_any_process(tmp_path, edit, world_toml, pattern):
    xml = (builtin_dir() / "ur5e.xml").read_text()
    if edit is not None:
        xml = xml.replace(*edit)
    scene = load_scene(_scene_with_world(tmp_path, world_toml, xml))
    from ftc_hw.sim_devices.host import WorldHost

    with pytest.raises(SceneError, match=pattern):
        WorldHost(scene, "hold", devices=[])


def test_a_true_model_file_is_the_world(tmp_path):
    xml = (builtin_dir() / "ur5e.xml").read_text().replace('mass="2.846"', 'mass="3.046"')
    assert 'mass="3.046"' in xml
    scene = load_scene(_scene_with_world(tmp_path, '[world]\nmodel = "true.xml"\n', xml))
    assert isinstance(scene.world, WorldSpec) and scene.world.model_path.name == "true.xml"
    heavier, _ = _still_reading(scene)
    base, _ = _still_reading(UR5E)
    assert float(np.mean(heavier[:, 2] - base[:, 2])) == pytest.approx(-0.2 * 9.80665, rel=0.01)


def test_every_difference_is_drawn():
    assert set(DIFFERENCES) == {"inertials", "friction", "torque_constant", "mount", "gain", "coloured_noise",
                                "thermal", "shell"}


@pytest.mark.parametrize("name", builtin_names())
def test_the_joint_controller_s_damping_is_stable_in_typical_draws(name):
    """The world applies its joint PD torque explicitly each step (Euler), so its damping is stable only while
    ``dt * max eig(M^-1 K_d) < 2``; over poses within the joint ranges a typical draw's lighter inertias must
    keep a margin (leng2016's kd of 60 reached 3.4, and its arm blew up at its first moves)."""
    scene = load_scene(name)
    lo, hi = ArmModel(scene).joint_limits()
    rng = np.random.default_rng(0)
    kd = np.diag(np.asarray(scene.robot.kd, dtype=float))
    worst = 0.0
    for seed in (0, 2):
        world = World(with_reality(scene, Reality.TYPICAL, seed=seed), ScenarioSetup(Hold(np.array(scene.robot.home))),
                      seed=1)
        m, d, c = world.model, world.data, world.joints.matrix
        full = np.zeros((m.nv, m.nv))
        for q in rng.uniform(lo, hi, size=(100, len(lo))):
            world.joints.set_qpos(q, d.qpos)
            mujoco.mj_forward(m, d)
            mujoco.mj_fullM(m, d, full)
            gain = np.linalg.solve(c.T @ full @ c, kd)
            worst = max(worst, m.opt.timestep * float(np.max(np.real(np.linalg.eigvals(gain)))))
    assert worst < 1.8
