"""The world's joint signals as a real arm's sensors give them: motor currents (torque constants that
change with the windings' temperature, torque ripple and cogging periodic in the motor angle), joint
friction that falls as the gears warm, and the joint torque sensors (offset, drift with temperature,
white noise, range). Where each number comes from: docs/reality.md.

The joint controller is taken to close its loop on torque (the drive's current loop gives the torque
asked for): the ripple, cogging and the warm torque constant show in the current the motor takes, not
in the motion. The joint torque sensors sit on the link side of the gears: they read the torque the
joint transmits, the motor torque less the friction MuJoCo applied (:func:`friction_torques`).
"""
from __future__ import annotations

import math

import mujoco
import numpy as np

from ftc_hw.model import JointMap
from ftc_hw.scene import JointTorqueSpec, Scene
from ftc_hw.scene.world_spec import WorldSpec

from ..thermal import ThermalModel

DEFAULT_GEAR_RATIO = 100.0  # ESTIMATE: harmonic drives in arms run 50-160:1 (UR's 101: ur5e.toml's estimate)
RIPPLE_PER_REV = 24.0  # ESTIMATE: commutation ripple at 6x the electrical frequency, 4 pole pairs
COGGING_PER_REV = 36.0  # ESTIMATE: cogging at the stator's slot count (36 slots)
THERMAL_EVERY_S = 0.01  # s between updates of the windings' temperature (its time constant is minutes)


def friction_torques(m: mujoco.MjModel, d: mujoco.MjData, out: np.ndarray) -> np.ndarray:
    """The joint friction MuJoCo applied at the last step, per dof (N m; against the motion): the damping
    (``qfrc_damper``) plus the friction-loss constraint forces (the efc rows of type friction-dof, each
    one dof's). Valid after ``mj_step2`` (or ``mj_forward``). ``out``: nv, overwritten."""
    np.copyto(out, d.qfrc_damper)
    nf = int(d.nf)
    if nf:
        ne = int(d.ne)
        np.add.at(out, d.efc_id[ne:ne + nf], d.efc_force[ne:ne + nf])
    return out


class JointThermal:
    """The windings' temperature above the model's (K per scene joint): a first-order model on the motor
    currents (``sim_devices/thermal.py``, the UR and DYNAMIXEL emulators' own), from the world's
    ``winding_start_K``. Updated every ``THERMAL_EVERY_S``."""

    def __init__(self, n: int, world: WorldSpec) -> None:
        start = np.zeros(n) if world.winding_start_K is None else np.asarray(world.winding_start_K, dtype=float)
        self.model = ThermalModel(n, ambient_c=0.0, gain_c_per_a2=world.winding_heating_K_per_A2,
                                  tau_s=world.winding_tau_s, start_c=0.0)
        self.model.temperature = start.copy()
        self.rise = self.model.temperature
        self._next = -math.inf

    def update(self, t: float, current: np.ndarray) -> bool:
        """Advance to ``t`` under ``current`` (A) when due; True when the temperature was updated."""
        if t < self._next:
            return False
        self._next = t + THERMAL_EVERY_S
        self.rise = self.model.update(t, current)
        return True


class MotorModel:
    """Motor currents from the joint torques: ``i = (tau - cogging) / (kt (1 + a dT) (1 + r sin(P th)))``
    with ``th = N q + th0`` the motor angle (gear ratio N, the rotor's angle th0 at joint angle 0), P
    ripple periods per motor turn, ``cogging = c sin(C th)``. Without ripple, cogging or a temperature
    coefficient: ``tau / kt``."""

    def __init__(self, scene: Scene, torque_constant: np.ndarray) -> None:
        w, n = scene.world, scene.n_joints
        self.kt = np.asarray(torque_constant, dtype=float)
        self.per_K = float(w.torque_constant_per_K)
        ratio = np.full(n, DEFAULT_GEAR_RATIO) if w.gear_ratio is None else np.asarray(w.gear_ratio, dtype=float)
        self.ratio = ratio
        self.offset = np.zeros(n) if w.motor_angle_offset is None else np.asarray(w.motor_angle_offset, dtype=float)
        # (amplitude, periods per joint radian, phase): sin(P th) = sin(P N q + P th0), per step one fused sine
        self.ripple = None if w.current_ripple is None or not np.any(w.current_ripple) else (
            np.asarray(w.current_ripple, dtype=float), RIPPLE_PER_REV * ratio, RIPPLE_PER_REV * self.offset)
        self.cogging = None if w.cogging_torque is None or not np.any(w.cogging_torque) else (
            np.asarray(w.cogging_torque, dtype=float), COGGING_PER_REV * ratio, COGGING_PER_REV * self.offset)
        self._kt_now = self.kt  # at the windings' last temperature (set_temperature)

    def set_temperature(self, rise: np.ndarray) -> None:
        """The windings' temperature above the model's (K per joint), for the currents from now on."""
        if self.per_K:
            self._kt_now = self.kt * (1.0 + self.per_K * rise)

    def current(self, tau: np.ndarray, q: np.ndarray) -> np.ndarray:
        kt = self._kt_now
        if self.ripple is not None:
            amp, freq, phase = self.ripple
            kt = kt * (1.0 + amp * np.sin(freq * q + phase))
        if self.cogging is not None:
            amp, freq, phase = self.cogging
            tau = tau - amp * np.sin(freq * q + phase)
        return tau / kt


class JointTorqueSensors:
    """The joint torque sensors' reading: the transmitted torque plus the scene's offsets and the world's
    (``joint_torque_offset``), a drift with the windings' temperature, white noise, clipped at the range."""

    def __init__(self, spec: JointTorqueSpec, world: WorldSpec, rng: np.random.Generator, noise: bool) -> None:
        self.spec = spec
        self.rng = rng
        self.noise = noise and bool(np.any(spec.noise_std > 0))
        offset = np.asarray(spec.offset, dtype=float)
        self.offset = offset if world.joint_torque_offset is None else offset + world.joint_torque_offset
        drift = world.joint_torque_drift_per_K
        self.drift = None if drift is None or not np.any(drift) else np.asarray(drift, dtype=float)
        self._high = np.asarray(spec.range, dtype=float)
        self._low = -self._high

    def read(self, tau_j: np.ndarray, rise: np.ndarray | None) -> np.ndarray:
        out = tau_j + self.offset
        if self.drift is not None and rise is not None:
            out = out + self.drift * rise
        if self.noise:
            out = out + self.rng.normal(size=out.shape) * self.spec.noise_std
        return np.minimum(np.maximum(out, self._low), self._high)


class JointFriction:
    """The scene joints' friction on the dofs their motors drive, scaled by the gears' temperature:
    ``(1 + friction_per_K dT)`` (at least a tenth), the grease's temperature taken as the windings'
    (ESTIMATE: the gear lags and stays cooler; the coefficient's source says which it was measured on)."""

    def __init__(self, m: mujoco.MjModel, jm: JointMap, viscous: np.ndarray, coulomb: np.ndarray,
                 stribeck: tuple[np.ndarray, np.ndarray] | None, per_K: float) -> None:
        self.m = m
        self.dofs, ratio = jm.dadr[jm.lead], jm.ratio[jm.lead]
        self.damping = viscous / ratio**2  # in the dof's units: b / ratio^2, f_c / |ratio|
        self.frictionloss = coulomb / np.abs(ratio)
        self.stribeck = stribeck
        self.per_K = per_K
        self.scale = np.ones(len(self.dofs))
        self.apply(None)

    def apply(self, rise: np.ndarray | None) -> None:
        """Set the model's friction at temperature rise ``rise`` (K per scene joint; None: the model's)."""
        if rise is not None and self.per_K:
            self.scale = np.maximum(1.0 + self.per_K * rise, 0.1)
        self.m.dof_damping[self.dofs] = self.damping * self.scale
        self.m.dof_frictionloss[self.dofs] = self.frictionloss * self.scale

    def stribeck_force(self, qvel: np.ndarray) -> np.ndarray | None:
        """The friction above Coulomb near standstill (Stribeck) per driven dof: ``excess exp(-(v / vs)^2)``,
        against the motion (smoothed through zero over a twentieth of vs); None without one."""
        if self.stribeck is None:
            return None
        excess, vs = self.stribeck
        v = qvel[self.dofs]
        return -(self.scale * excess) * np.exp(-np.square(v / vs)) * np.tanh(v / (0.05 * vs))
