"""Raw sensor wrench -> external contact wrench: subtract the bias and the arm's own loads.

The arm's loads are computed only as far as the level asks (``ArmModel.arm_loads``): ``bias``
computes nothing, ``gravity`` the static weight (q only), ``dynamics`` MuJoCo's inverse dynamics with
(q, qd, qdd). A payload from the calibration is part of the arm model.
"""
from __future__ import annotations

import numpy as np

from ..model import ArmModel, Payload
from ..scene import CompensationLevel


class Compensator:
    def __init__(self, model: ArmModel, level: CompensationLevel | None = None, bias=None,
                 payload: Payload | None = None) -> None:
        if payload is not None and payload != model.payload:
            model = ArmModel(model.scene, payload)
        self.model = model
        self.level: CompensationLevel = level or model.scene.compensation
        if self.level not in ("bias", "gravity", "dynamics"):
            raise ValueError(f"level must be bias, gravity or dynamics, got {self.level!r}")
        self.bias = np.zeros(6) if bias is None else np.asarray(bias, dtype=float).reshape(6).copy()

    def loads(self, q, qd=None, qdd=None, joint_torques: bool = False):
        """The arm's own wrench on the sensor and (optionally) the joint torques it needs."""
        return self.model.arm_loads(q, qd, qdd, self.level, joint_torques)

    def external(self, raw, q, qd=None, qdd=None) -> np.ndarray:
        """The external contact wrench (sensor frame, the scene's sign convention)."""
        return np.asarray(raw, dtype=float) - self.bias - self.loads(q, qd, qdd)[0]

    def tare(self, raw, q, qd=None, qdd=None) -> None:
        """Re-zero: take the current reading as no-contact (the arm still and untouched). At the
        ``bias`` level this folds the arm's weight at this pose into the bias."""
        self.bias = np.asarray(raw, dtype=float) - self.loads(q, qd, qdd)[0]
