"""Joint sensing in a world that is not the model (issue 37): current ripple and cogging in the motor
angle, the torque constants and joint friction changing with the windings' temperature, joint torque
sensors' offsets and drift; drawn per reality, seeded, and read from a scene's ``[world]`` table."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ftc_hw.scene import JointTorqueSpec, SceneError, load_scene
from ftc_hw.scene.loader import builtin_dir
from ftc_hw.sim_devices.world import JOINT_DIFFERENCES, Hold, ScenarioSetup, Sinusoid, World, with_reality
from ftc_hw.sim_devices.world.joint_sensing import RIPPLE_PER_REV
from ftc_hw.sim_devices.world.reality import TOLERANCES, Reality

pytestmark = pytest.mark.compute  # computes only (nothing timed): runs with the others on every core

UR5E = load_scene("ur5e")
N = UR5E.n_joints
HOME = np.array(UR5E.robot.home)
SWEEP = Sinusoid(HOME, np.array([0.6, 0.4, 0.5, 0.8, 0.8, 1.0]), 0.4)
SENSORS = JointTorqueSpec(noise_std=np.zeros(N), range=np.full(N, 1e4), offset=np.zeros(N))


def _true(scene, **world):
    return dataclasses.replace(scene, world=dataclasses.replace(scene.world, **world))


def test_ripple_and_cogging_are_in_the_current_periodic_in_the_motor_angle():
    ripple, ratio = np.full(N, 0.03), np.full(N, 101.0)
    scene = _true(UR5E, current_ripple=ripple, gear_ratio=ratio, motor_angle_offset=np.full(N, 0.4))
    world = World(scene, ScenarioSetup(SWEEP), noise=False)
    kt = UR5E.robot.torque_constant
    for state, _ in world.run(0.2):
        want = state.tau / (kt * (1.0 + ripple * np.sin(RIPPLE_PER_REV * (ratio * state.q + 0.4))))
        np.testing.assert_allclose(state.current, want, rtol=1e-12)
    assert not np.allclose(state.current, state.tau / kt, rtol=1e-3)
    cog = _true(UR5E, cogging_torque=np.full(N, 0.2), gear_ratio=ratio)
    state = World(cog, ScenarioSetup(SWEEP), noise=False).step()
    assert np.abs(state.current * kt - state.tau).max() > 0.01  # the cogging, up to 0.2 N m


def test_a_warm_arm_has_less_friction_and_weaker_motors():
    warm = dict(winding_start_K=np.full(N, 20.0), friction_per_K=-0.01, torque_constant_per_K=-0.001)
    cold_world = World(dataclasses.replace(UR5E, joint_torque=SENSORS), ScenarioSetup(SWEEP), noise=False)
    warm_world = World(_true(dataclasses.replace(UR5E, joint_torque=SENSORS), **warm), ScenarioSetup(SWEEP),
                       noise=False)
    for _ in range(1200):  # 0.6 s
        cold, hot = cold_world.step(), warm_world.step()
    rise = warm_world.thermal.rise
    assert np.all((rise > 19.0) & (rise <= 20.0))  # cooling towards the currents' steady rise (none set: 0 K)
    np.testing.assert_allclose(warm_world.friction.scale, 1.0 - 0.01 * rise, rtol=1e-12)
    kt = UR5E.robot.torque_constant * (1.0 - 0.001 * rise)
    np.testing.assert_allclose(hot.current, hot.tau / kt, rtol=1e-12)
    # the friction the joints apply while sweeping (none stands still at 0.6 s) is about 20 % less
    ratio = (hot.tau - hot.tau_j) / (cold.tau - cold.tau_j)
    np.testing.assert_allclose(ratio, 0.8, atol=0.03)


def test_joint_torque_sensor_offsets_and_drift_from_the_world():
    offset, drift = np.linspace(-0.3, 0.3, N), np.full(N, 0.01)
    scene = _true(dataclasses.replace(UR5E, joint_torque=SENSORS), joint_torque_offset=offset,
                  joint_torque_drift_per_K=drift, winding_start_K=np.full(N, 10.0))
    world = World(scene, ScenarioSetup(Hold(HOME)), noise=False)
    state = world.step()
    np.testing.assert_allclose(world.read_joint_torques(state) - state.tau_j, offset + drift * world.thermal.rise,
                               atol=1e-12)


@pytest.mark.parametrize("reality", [Reality.TYPICAL, Reality.HARSH])
def test_joint_sensing_draws_are_seeded_within_tolerance_and_keep_the_other_draws(reality):
    scene = dataclasses.replace(UR5E, joint_torque=dataclasses.replace(SENSORS, range=np.full(N, 80.0)))
    tol = TOLERANCES[reality]
    w = with_reality(scene, reality, seed=4).world
    assert np.all((w.current_ripple >= 0) & (w.current_ripple <= tol.ripple_rel))
    assert np.all(w.cogging_torque <= tol.cogging_rel * UR5E.robot.friction_coulomb)
    assert tol.torque_constant_per_K[0] <= w.torque_constant_per_K <= tol.torque_constant_per_K[1]
    assert tol.friction_per_K[0] <= w.friction_per_K <= tol.friction_per_K[1] < 0
    assert np.all(np.abs(w.winding_start_K) <= tol.winding_start_K)
    assert np.all(np.abs(w.joint_torque_offset) <= tol.torque_offset_rel * 80.0)
    assert not w.is_ideal and w.joint_sensing_differs
    # the F/T, inertial and friction draws are what they were before the joint sensing was drawn
    before = with_reality(scene, reality, seed=4, only=("gain", "friction", "inertials")).world
    np.testing.assert_array_equal(before.sensor_gain, w.sensor_gain)
    np.testing.assert_array_equal(before.friction_coulomb, w.friction_coulomb)
    only = with_reality(scene, reality, seed=4, only=JOINT_DIFFERENCES[:1]).world
    np.testing.assert_array_equal(only.current_ripple, w.current_ripple)
    assert only.friction_per_K == 0.0 and only.joint_torque_offset is None


def test_the_world_table_takes_the_joint_sensing_keys(tmp_path):
    text = (builtin_dir() / "ur5e.toml").read_text()
    (tmp_path / "ur5e.xml").write_text((builtin_dir() / "ur5e.xml").read_text())
    good = ("\n[world]\ngear_ratio = [101, 101, 101, 101, 101, 101]\n"
            "current_ripple = [0.02, 0.02, 0.02, 0.01, 0.01, 0.01]\n"
            "torque_constant_per_K = -0.0011\nfriction_per_K = -0.01\nwinding_start_K = [5, 5, 5, 5, 5, 5]\n"
            "winding_heating_K_per_A2 = 0.5\njoint_torque_offset = [0.1, 0, 0, 0, 0, 0]\n")
    path = tmp_path / "scene.toml"
    path.write_text(text + good)
    w = load_scene(path).world
    assert w.torque_constant_per_K == -0.0011 and w.friction_per_K == -0.01 and w.current_ripple[0] == 0.02
    assert w.winding_tau_s == 900.0 and w.joint_thermal and not w.is_ideal
    for bad, key in (("friction_per_K = 0.5", "world.friction_per_K"),
                     ("current_ripple = [0.6, 0, 0, 0, 0, 0]", "world.current_ripple"),
                     ("gear_ratio = [0, 1, 1, 1, 1, 1]", "world.gear_ratio")):
        path.write_text(text + "\n[world]\n" + bad + "\n")
        with pytest.raises(SceneError, match=key.replace(".", r"\.")):
            load_scene(path)
