"""Identification from the joints against a drawn arm (docs/measurements/reality.md): the world in this
process (no emulators), the planned excitation's joint state and motor currents at 500 Hz, the fit of
``ftc_hw.calibration.joint_ident``, and its torque constants, friction and predicted currents against
the drawn arm's. One JSON line per seed.

    .venv/bin/python scripts/measure_joint_ident.py ur5e typical 0,1,2,3,4 [seconds]
"""
from __future__ import annotations

import json
import sys
import time

import numpy as np

from ftc_hw.calibration.joint_ident import JointIdentifier
from ftc_hw.calibration.joint_motion import V_EPS, JointMotionData
from ftc_hw.model import ArmModel
from ftc_hw.model.inertials import body_params
from ftc_hw.model.true_arm import compile_true_arm, true_arm_spec
from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.world import World, build_scenario, with_reality

RATE_HZ = 500.0  # a UR controller's RTDE rate


def record(true_scene, seed: int, seconds: float) -> JointMotionData:
    setup = build_scenario("excitation", true_scene, ArmModel(true_scene), seed, seconds + 2.0)
    world = World(true_scene, setup, seed=seed)
    every = int(round(true_scene.sensor.rate_hz / RATE_HZ))
    rows = [(s.t, s.q, s.qd, world.read_current(s)) for k, (s, _) in enumerate(world.run(seconds + 0.5))
            if k % every == 0]
    t, q, qd, current = (np.array([r[i] for r in rows]) for i in range(4))
    return JointMotionData(t, q, qd, current)


def held_out(scene, true_scene, fit, seed: int, states: int = 300) -> dict[str, list[float]]:
    """RMS error (N m at the true torque constants) of the motor currents the identified and the scene's
    model predict at random moving states, against the drawn arm's (friction and Stribeck included)."""
    w, r = true_scene.world, scene.robot
    nominal = ArmModel(scene)
    tm = compile_true_arm(true_scene, true_arm_spec(true_scene, shell="none"))
    true_arm = ArmModel(scene, inertials={b: body_params(tm, tm.body(b).id)
                                          - body_params(nominal.model, nominal.model.body(b).id) for b in fit.bodies})
    ident = ArmModel(scene, inertials=dict(zip(fit.bodies, fit.delta_pi, strict=True)))
    stribeck = w.friction_stribeck if w.friction_stribeck is not None else np.zeros(scene.n_joints)
    rng = np.random.default_rng(200 + seed)
    home, n = np.asarray(r.home), scene.n_joints
    err_id, err_nom = [], []
    for _ in range(states):
        q = home + rng.uniform(-1, 1, n)
        v = rng.choice([-1, 1], n) * rng.uniform(0.1, 1.0, n)
        a = rng.normal(size=n)
        sg = np.tanh(v / V_EPS)
        i_true = (true_arm.joint_torques(q, v, a) + w.friction_viscous * v + w.friction_coulomb * sg
                  + stribeck * np.exp(-(v / w.stribeck_velocity) ** 2) * sg) / w.torque_constant
        i_id = (ident.joint_torques(q, v, a) + fit.friction_viscous * v + fit.friction_coulomb * sg
                + fit.rotor_inertia * a) / fit.torque_constant
        i_nom = (nominal.joint_torques(q, v, a) + np.asarray(r.friction_viscous) * v
                 + np.asarray(r.friction_coulomb) * sg) / np.asarray(r.torque_constant)
        err_id.append((i_id - i_true) * w.torque_constant)
        err_nom.append((i_nom - i_true) * w.torque_constant)
    return {"current_rms_identified_Nm": np.sqrt(np.mean(np.square(err_id), axis=0)).tolist(),
            "current_rms_scene_Nm": np.sqrt(np.mean(np.square(err_nom), axis=0)).tolist()}


def run(name: str, reality: str, seed: int, seconds: float) -> dict:
    scene = load_scene(name).with_sensing(["currents"])
    true_scene = with_reality(scene, reality, seed)
    data = record(true_scene, seed, seconds)
    t0 = time.perf_counter()
    fit = JointIdentifier(ArmModel(scene)).fit(data)
    took = time.perf_counter() - t0
    w = true_scene.world
    return {"scene": name, "reality": reality, "seed": seed, "seconds": seconds, "fit_s": took,
            "verdict": fit.verdict, "untold": fit.untold, "scale_std": fit.scale_std,
            "torque_constant_rel_err": (fit.torque_constant / w.torque_constant - 1).tolist(),
            "viscous_err": (fit.friction_viscous - w.friction_viscous).tolist(),
            "coulomb_err": (fit.friction_coulomb - w.friction_coulomb).tolist(),
            "residual_std_Nm": fit.residual_std["currents"].tolist(),
            "residual_std_before_Nm": fit.residual_std_before["currents"].tolist(),
            **held_out(scene, true_scene, fit, seed)}


if __name__ == "__main__":
    seconds = float(sys.argv[4]) if len(sys.argv) > 4 else 120.0
    for s in sys.argv[3].split(","):
        print(json.dumps(run(sys.argv[1], sys.argv[2], int(s), seconds)), flush=True)
