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
                 payload: Payload | None = None, gain=None, frame=None, contact_gain=None) -> None:
        """``gain``: the sensor's identified linear error, ``reading = gain @ (loads + contact) + bias``
        (None: exact), as free-motion identification estimates it (:mod:`ftc_hw.calibration.free_motion`):
        applied to the predicted loads and undone on the contact's wrench, which the same sensor reads;
        ``contact_gain``: what is undone there instead (the terms the identification told; None: ``gain``).
        ``frame``: the sensor's reading of a wrench given in the model's sensor frame (6 x 6, e.g. a
        calibrated mount yaw), undone on every reading (None: the model's frame)."""
        if payload is not None and payload != model.payload:
            model = ArmModel(model.scene, payload, model.inertials)
        self.model = model
        self.level: CompensationLevel = level or model.scene.compensation
        if self.level not in ("bias", "gravity", "dynamics"):
            raise ValueError(f"level must be bias, gravity or dynamics, got {self.level!r}")
        self.bias = np.zeros(6) if bias is None else np.asarray(bias, dtype=float).reshape(6).copy()
        self._contact_fixed = contact_gain is not None
        self.gain = gain
        if contact_gain is not None:
            self._contact_inv = np.linalg.inv(np.asarray(contact_gain, dtype=float).reshape(6, 6))
        self.frame = None if frame is None else np.asarray(frame, dtype=float).reshape(6, 6).copy()
        self.frame_inv = None if frame is None else np.linalg.inv(self.frame)

    @property
    def gain(self) -> np.ndarray | None:
        return self._gain

    @gain.setter
    def gain(self, gain) -> None:
        self._gain = None if gain is None else np.asarray(gain, dtype=float).reshape(6, 6).copy()
        if not self._contact_fixed:
            self._contact_inv = None if gain is None else np.linalg.inv(self._gain)

    def loads(self, q, qd=None, qdd=None, joint_torques: bool = False):
        """The arm's own wrench on the sensor as read (the gain applied) and, if asked, the joint
        torques it needs."""
        loads, tau = self.model.arm_loads(q, qd, qdd, self.level, joint_torques)
        return (loads if self.gain is None else self.gain @ loads), tau

    def external(self, raw, q, qd=None, qdd=None) -> np.ndarray:
        """The external contact wrench (sensor frame, the scene's sign convention)."""
        return self.contact_wrench(self.unbiased(raw), self.loads(q, qd, qdd)[0])

    def contact_wrench(self, unbiased: np.ndarray, loads: np.ndarray) -> np.ndarray:
        """What is left of a reading (without its bias) once the arm's loads as read are taken away,
        with the sensor's gain undone."""
        rest = unbiased - loads
        return rest if self._contact_inv is None else self._contact_inv @ rest

    def unbiased(self, raw) -> np.ndarray:
        """The reading without its bias, in the model's sensor frame."""
        w = np.asarray(raw, dtype=float) - self.bias
        return w if self.frame_inv is None else self.frame_inv @ w

    def tare(self, raw, q, qd=None, qdd=None) -> None:
        """Re-zero: take the current reading as no-contact (the arm still and untouched). At the
        ``bias`` level this folds the arm's weight at this pose into the bias."""
        loads = self.loads(q, qd, qdd)[0]
        self.bias = np.asarray(raw, dtype=float) - (loads if self.frame is None else self.frame @ loads)
