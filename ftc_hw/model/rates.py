"""The rate a simulated scene's samples come at: its F/T sensor's, else its joints'."""
from __future__ import annotations

from ..scene import Scene
from ..scene.device_params import KINDS

# ESTIMATE: an arm controller's usual cycle (Franka's 1 kHz; UR's 125 Hz CB3, 500 Hz e-Series)
DEFAULT_JOINT_RATE_HZ = 1000.0


def sample_rate_hz(scene: Scene) -> float:
    """The world's sample rate, Hz: the F/T sensor's ``rate_hz`` when the scene has one; else the joint
    torque sensors' ``[joint_torque] rate_hz``; else the first device's ``frequency`` param (the arm's
    stream, e.g. a UR's RTDE rate: given, or its kind's default); else 1000 Hz."""
    if scene.sensor is not None:
        return float(scene.sensor.rate_hz)
    if scene.joint_torque is not None:
        return float(scene.joint_torque.rate_hz)
    for d in scene.devices:
        kind = KINDS.get(d.kind)
        param = kind.param("frequency") if kind is not None else None
        value = d.params.get("frequency", param.default if param is not None else None)
        if value is not None:
            return float(value)
    return DEFAULT_JOINT_RATE_HZ
