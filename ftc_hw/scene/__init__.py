"""Scenes: TOML files that say what a setup is. Built-ins ship in ``ftc_hw/scene/builtin``."""
from .errors import SceneError
from .loader import builtin_names, load_scene, resolve, variant_names
from .overrides import load_rig_scene
from .schema import (
    COMPENSATION_LEVELS,
    SENSING_KINDS,
    SENSOR_MOUNTS,
    CompensationLevel,
    Coupling,
    DeviceSpec,
    JointTorqueSpec,
    RobotSpec,
    Scene,
    Sensing,
    SensingKind,
    SensorMount,
    SensorSpec,
    SignConvention,
    TouchableLink,
)

__all__ = [
    "COMPENSATION_LEVELS", "SENSING_KINDS", "SENSOR_MOUNTS", "CompensationLevel", "Coupling", "DeviceSpec",
    "JointTorqueSpec", "RobotSpec", "Scene", "SceneError", "Sensing", "SensingKind", "SensorMount", "SensorSpec",
    "SignConvention", "TouchableLink", "builtin_names", "load_rig_scene", "load_scene",
    "resolve", "variant_names",
]
