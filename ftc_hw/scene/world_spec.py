"""How the simulated world's arm differs from the pipeline's model: a scene's ``[world]`` table.

The pipeline always works from ``[robot]`` and ``[sensor]``; the world (``ftc sim`` and every
``--sim``) builds the *true* arm from them plus these differences. Empty (the default): the world is
the model, the ``ideal`` reality. Units: SI; docs/reality.md lists every key.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


def _frozen(values) -> np.ndarray:
    arr = np.array(values, dtype=float)
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True)
class InertialError:
    """One body's true inertials against the model's: mass x ``mass_scale``, centre of mass moved by
    ``com_offset`` (m, the body's frame), rotational inertia about the centre x ``inertia_scale``."""

    mass_scale: float = 1.0
    com_offset: np.ndarray = field(default_factory=lambda: _frozen([0.0, 0.0, 0.0]))
    inertia_scale: float = 1.0

    @property
    def is_exact(self) -> bool:
        return self.mass_scale == 1.0 and self.inertia_scale == 1.0 and not np.any(self.com_offset)


@dataclass(frozen=True)
class WorldSpec:
    """The true arm, sensor and surface, as differences from the scene's model. ``None``: as modelled."""

    model_path: Path | None = None  # MJCF or URDF of the true arm: the model's joint and body names
    inertials: Mapping[str, InertialError] = field(default_factory=dict)
    friction_coulomb: np.ndarray | None = None  # N m per scene joint
    friction_viscous: np.ndarray | None = None  # N m s / rad
    friction_stribeck: np.ndarray | None = None  # N m: breakaway friction above Coulomb at rest
    stribeck_velocity: float = 0.02  # rad/s: the speed over which the Stribeck excess fades (exp(-(v/vs)^2))
    torque_constant: np.ndarray | None = None  # N m / A at the joint: the motors' true constants
    sensor_offset: np.ndarray = field(default_factory=lambda: _frozen([0.0, 0.0, 0.0]))  # m, sensor frame
    sensor_rotation: np.ndarray = field(default_factory=lambda: _frozen([0.0, 0.0, 0.0]))  # rad, rotation vector
    sensor_gain: np.ndarray = field(default_factory=lambda: _frozen(np.eye(6)))  # reading = gain @ true wrench
    coloured_noise_std: np.ndarray = field(default_factory=lambda: _frozen([0.0] * 6))  # N, N m (stationary std)
    coloured_noise_tau_s: float = 1.0  # s: correlation time of the coloured (first-order Gauss-Markov) noise
    temperature_drift: np.ndarray = field(default_factory=lambda: _frozen([0.0] * 6))  # N/K, N m/K
    temperature_rise_K: float = 0.0  # K: the sensor warms by this, 1 - exp(-t / tau), from the run's start
    temperature_tau_s: float = 600.0  # s
    shell_offset: float = 0.0  # m: the touched surface lies this far outside the model's primitives
    shell_offsets: Mapping[str, float] = field(default_factory=dict)  # m, per geom
    vendor_shell: str | None = None  # the vendor's meshes (ftc_hw.scene.vendor) are the touched surface
    vendor_shell_shift: Mapping[str, np.ndarray] = field(default_factory=dict)  # m, per body (its frame): the
    # real shell's offset from the vendor's meshes (casting and assembly tolerance)
    # joint sensing (sim_devices/world/joint_sensing.py; None: as modelled, i.e. none of it)
    gear_ratio: np.ndarray | None = None  # motor turns per joint turn, per scene joint (None: 100, ESTIMATE)
    motor_angle_offset: np.ndarray | None = None  # rad: each rotor's angle at joint angle 0 (the ripple's phase)
    current_ripple: np.ndarray | None = None  # relative torque-per-amp ripple amplitude, periodic in the motor angle
    cogging_torque: np.ndarray | None = None  # N m at the joint: cogging amplitude, periodic in the motor angle
    torque_constant_per_K: float = 0.0  # relative change of the torque constants per K of winding temperature
    friction_per_K: float = 0.0  # relative change of joint friction (Coulomb, viscous, Stribeck) per K
    winding_start_K: np.ndarray | None = None  # K per joint: the windings at the start, above the model's temperature
    winding_heating_K_per_A2: float = 0.0  # K per A^2: a winding's steady rise above the model's temperature
    winding_tau_s: float = 900.0  # s: the windings' thermal time constant
    joint_torque_offset: np.ndarray | None = None  # N m per joint, added to the [joint_torque] sensors' offsets
    joint_torque_drift_per_K: np.ndarray | None = None  # N m per K of winding temperature, per joint

    @property
    def joint_thermal(self) -> bool:
        """The windings' temperature changes something: the torque constants, the friction or the
        joint torque sensors' offsets."""
        return bool(self.torque_constant_per_K or self.friction_per_K or (
            self.joint_torque_drift_per_K is not None and np.any(self.joint_torque_drift_per_K)))

    @property
    def is_ideal(self) -> bool:
        return (self.model_path is None and all(e.is_exact for e in self.inertials.values())
                and self.friction_coulomb is None and self.friction_viscous is None
                and (self.friction_stribeck is None or not np.any(self.friction_stribeck))
                and self.torque_constant is None and not np.any(self.sensor_offset)
                and not np.any(self.sensor_rotation) and np.array_equal(self.sensor_gain, np.eye(6))
                and not np.any(self.coloured_noise_std)
                and not (np.any(self.temperature_drift) and self.temperature_rise_K)
                and self.shell_offset == 0.0 and not any(self.shell_offsets.values())
                and self.vendor_shell is None and not self.joint_sensing_differs)

    @property
    def joint_sensing_differs(self) -> bool:
        """Motor currents or joint torque readings differ from the model's (ripple, cogging, temperature,
        torque-sensor offsets)."""
        return bool(self.joint_thermal or any(v is not None and np.any(v) for v in (
            self.current_ripple, self.cogging_torque, self.joint_torque_offset)))

    def shell_of(self, geom: str) -> float:
        """The shell offset (m) of one geom: its own if given, else the common one."""
        return float(self.shell_offsets.get(geom, self.shell_offset))


IDEAL = WorldSpec()
