"""The scene: what a setup is (robot model, F/T sensor, gravity, touchable links, compensation, devices).

All quantities are SI (m, kg, s, N, N m, rad). See docs/conventions.md for frames and signs.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from .errors import SceneError
from .world_spec import IDEAL, WorldSpec

SignConvention = Literal["base_on_arm", "arm_on_base"]
SensorMount = Literal["base", "flange"]
SENSOR_MOUNTS: tuple[SensorMount, ...] = ("base", "flange")
SensingKind = Literal["base_ft", "flange_ft", "joint_torques", "currents"]
SENSING_KINDS: tuple[SensingKind, ...] = ("base_ft", "flange_ft", "joint_torques", "currents")
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
    max_speed: np.ndarray | None = None  # rad/s per joint: what a motion the bridge commands may reach (None: unknown)
    max_acceleration: np.ndarray | None = None  # rad/s^2 per joint (None: unknown)


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
    # "base": under the arm, it carries the whole arm; "flange": between the flange and the tool, it
    # carries only the bodies beyond its site (tool, payload) and sees only contacts on them
    mount: SensorMount = "base"

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
class JointTorqueSpec:
    """Torque sensors in the joints, on the link side of the gears (Franka's ``tau_J``): they read the
    torque the joint transmits, i.e. the motor's torque less the gear's friction. Per joint, N m."""

    noise_std: np.ndarray  # 1 sigma white noise
    range: np.ndarray  # symmetric limit of the reading
    offset: np.ndarray  # the simulated sensors' offsets (the world's truth; identification estimates them)
    rate_hz: float = 1000.0


@dataclass(frozen=True)
class Sensing:
    """Which sensing a scene has, or which of it the pipeline uses: any of :data:`SENSING_KINDS`.
    ``base_ft`` / ``flange_ft``: the scene's F/T sensor by its mount; ``joint_torques``: joint torque
    sensors; ``currents``: motor currents through the torque constants and the joints' friction."""

    kinds: frozenset[SensingKind]

    @property
    def ft(self) -> SensorMount | None:
        """The F/T sensor's mount when an F/T sensor is used, else None."""
        return "base" if "base_ft" in self.kinds else "flange" if "flange_ft" in self.kinds else None

    @property
    def currents(self) -> bool:
        return "currents" in self.kinds

    @property
    def joint_torques(self) -> bool:
        return "joint_torques" in self.kinds

    @property
    def joint(self) -> bool:
        """Joint signals (currents or torques) are used."""
        return self.currents or self.joint_torques

    def label(self) -> str:
        """e.g. ``currents + flange_ft`` (in :data:`SENSING_KINDS`' order)."""
        return " + ".join(k for k in SENSING_KINDS if k in self.kinds) or "nothing"


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
    sensor: SensorSpec | None  # the 6-axis F/T sensor (``[sensor]``), None: the scene has none
    touchable: tuple[TouchableLink, ...]
    compensation: CompensationLevel
    devices: tuple[DeviceSpec, ...]
    world: WorldSpec = IDEAL  # how the simulated world's arm differs from this model (``[world]``)
    joint_torque: JointTorqueSpec | None = None  # joint torque sensors (``[joint_torque]``), if any
    has_currents: bool = True  # the arm reports motor currents (``[robot] torque_constant`` given)
    uses: frozenset[SensingKind] | None = None  # ``[sensing] uses``; None: all the scene has

    @property
    def available(self) -> Sensing:
        """The sensing the scene has."""
        kinds: set[SensingKind] = set()
        if self.sensor is not None:
            kinds.add("base_ft" if self.sensor.mount == "base" else "flange_ft")
        if self.joint_torque is not None:
            kinds.add("joint_torques")
        if self.has_currents:
            kinds.add("currents")
        return Sensing(frozenset(kinds))

    @property
    def sensing(self) -> Sensing:
        """The sensing the pipeline uses: ``[sensing] uses``, else all the scene has."""
        return self.available if self.uses is None else Sensing(self.uses)

    def with_sensing(self, kinds) -> Scene:
        """This scene using only ``kinds`` (names of :data:`SENSING_KINDS`) of what it has; the hardware
        (and so the simulated world) stays as it is. A ``SceneError`` names what it lacks."""
        wanted = frozenset(kinds)
        unknown = sorted(wanted - set(SENSING_KINDS))
        if unknown:
            raise SceneError(self.path, "sensing.uses", f"unknown sensing {unknown[0]!r} "
                             f"(known: {', '.join(SENSING_KINDS)})")
        missing = sorted(wanted - self.available.kinds)
        if missing:
            raise SceneError(self.path, "sensing.uses", f"scene {self.name!r} has no {', '.join(missing)} "
                             f"(it has: {self.available.label()})")
        if not wanted:
            raise SceneError(self.path, "sensing.uses", "expected at least one kind of sensing")
        return dataclasses.replace(self, uses=wanted)

    def require_ft(self, purpose: str) -> SensorSpec:
        """The scene's F/T sensor; a ``SceneError`` saying that ``purpose`` needs one when it has none."""
        if self.sensor is None:
            raise SceneError(self.path, "sensor", f"scene {self.name!r} has no F/T sensor: {purpose} needs one "
                             f"(it has: {self.available.label()})")
        return self.sensor

    @property
    def n_joints(self) -> int:
        return len(self.robot.joints)

    def touchable_link(self, name: str) -> TouchableLink | None:
        return next((t for t in self.touchable if t.link == name), None)
