"""The arm model (on MuJoCo)."""
from .arm import ArmModel, Contact, PosedSurface, Surface, apply_point_force, pose
from .build import (
    FORCE_SENSOR,
    TORQUE_SENSOR,
    Payload,
    add_ft_sensors,
    attach_payload,
    descends,
    load_spec,
)
from .joint_map import JointMap

__all__ = [
    "FORCE_SENSOR", "TORQUE_SENSOR", "ArmModel", "Contact", "JointMap", "Payload", "PosedSurface", "Surface",
    "add_ft_sensors", "apply_point_force", "attach_payload", "descends", "load_spec", "pose",
]
