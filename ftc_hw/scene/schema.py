"""The scene: what a setup is (robot model, F/T sensor, gravity, touchable links, compensation, devices).

All quantities are SI (m, kg, s, N, N m, rad). See docs/conventions.md for frames and signs.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from .world_spec import IDEAL, WorldSpec

SignConvention = Literal["base_on_arm", "arm_on_base"]
CompensationLevel = Literal["bias", "gravity", "dynamics"]
COMPENSATION_LEVELS: tuple[CompensationLevel, ...] = ("bias", "gravity", "dynamics")
SIGN_CONVENTIONS: tuple[SignConvention, ...] = ("base_on_arm", "arm_on_base")


def _frozen(values: Any) -> np.ndarray:
    arr = np.array(values, dtype=float)
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True)
class Coupling:
    """A scene joint that is no joint of the robot model but drives several of them at fixed ratios:
    model joint ``drives[k]`` = ``ratios[k]`` x the scene joint (a gripper's pinion turning two racks:
    m per rad). The model joints it drives are not listed among the scene's joints."""

    joint: str
    drives: tuple[str, ...]
    ratios: tuple[float, ...]


@dataclass(frozen=True)
class RobotSpec:
    model_path: Path
    joints: tuple[str, ...]
    home: np.ndarray
    flange: str | None
    torque_constant: np.ndarray  # N m / A, at the joint
    friction_viscous: np.ndarray  # N m s / rad
    friction_coulomb: np.ndarray  # N m
    kp: np.ndarray  # simulated world's joint PD controller, N m / rad
    kd: np.ndarray  # N m s / rad
    current_noise_std: np.ndarray  # A, the simulated current sensor's noise
    couplings: tuple[Coupling, ...] = ()  # scene joints that drive several model joints
    surface_tolerance: float = 0.0  # m, 1 sigma: how far the real shell may lie from the model's surfaces
    vendor_shell: str | None = None  # the vendor's meshes of this arm (ftc_hw.scene.vendor), if any


@dataclass(frozen=True)
class SensorSpec:
    site: str
    reports: SignConvention
    range: np.ndarray  # symmetric saturation limits, [N]*3 + [N m]*3
    noise_std: np.ndarray  # per-axis Gaussian noise standard deviation
    quantization: np.ndarray  # LSB per axis, 0 = none
    rate_hz: float
    bias: np.ndarray  # the simulated sensor's bias (the world's truth; calibration estimates it)
    drift_per_s: np.ndarray
    # 1 sigma, relative: each gain and crosstalk term (crosstalk in units of the two axes' ranges)
    accuracy: float = 0.005

    @property
    def noise_cov(self) -> np.ndarray:
        """Sensor noise covariance (6x6, diagonal), including the quantization noise LSB^2/12."""
        return np.diag(self.noise_std**2 + self.quantization**2 / 12.0)

    @property
    def reading_sign(self) -> float:
        """The one place the sign convention is decoded: +1 when the sensor reads the wrench its mount
        exerts on the arm (``base_on_arm``, MuJoCo's force/torque sensor convention), -1 when it reads
        the arm's on the mount (``arm_on_base``). ``reading = reading_sign * base_on_arm wrench``;
        a contact (p, c x p) on the arm changes the reading by ``-reading_sign * (p, c x p)``."""
        return 1.0 if self.reports == "base_on_arm" else -1.0


@dataclass(frozen=True)
class TouchableLink:
    link: str
    pulls: bool = False


@dataclass(frozen=True)
class DeviceSpec:
    name: str
    kind: str
    transport: str
    address: str | None = None
    params: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Scene:
    name: str
    description: str
    path: Path
    robot: RobotSpec
    gravity: np.ndarray  # m/s^2, base frame
    sensor: SensorSpec
    touchable: tuple[TouchableLink, ...]
    compensation: CompensationLevel
    devices: tuple[DeviceSpec, ...]
    world: WorldSpec = IDEAL  # how the simulated world's arm differs from this model (``[world]``)

    @property
    def n_joints(self) -> int:
        return len(self.robot.joints)

    def touchable_link(self, name: str) -> TouchableLink | None:
        return next((t for t in self.touchable if t.link == name), None)
