"""The arm model (on MuJoCo)."""
from .arm import ArmModel, Contact, PosedSurface, Surface, apply_point_force, pose
from .build import (
    FORCE_SENSOR,
    TORQUE_SENSOR,
    Payload,
    add_ft_sensors,
    arm_bodies,
    attach_payload,
    descends,
    ft_site_id,
    load_spec,
)
from .joint_map import JointMap
from .rates import sample_rate_hz

__all__ = [
    "FORCE_SENSOR", "TORQUE_SENSOR", "ArmModel", "Contact", "JointMap", "Payload", "PosedSurface", "Surface",
    "add_ft_sensors", "apply_point_force", "arm_bodies", "attach_payload", "descends", "ft_site_id", "load_spec",
    "pose", "sample_rate_hz",
]
