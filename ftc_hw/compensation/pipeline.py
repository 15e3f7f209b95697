"""Raw sensor wrench -> external contact wrench: subtract the bias and the arm's own loads.

The arm's loads are computed only as far as the level asks: ``bias`` computes nothing,
``gravity`` the static weight (q only), ``dynamics`` MuJoCo's inverse dynamics with (q, qd, qdd).
"""
from __future__ import annotations

import numpy as np

from ..model import ArmModel
from ..scene import CompensationLevel


class Compensator:
    def __init__(self, model: ArmModel, level: CompensationLevel | None = None, bias=None) -> None:
        self.model = model
        self.level: CompensationLevel = level or model.scene.compensation
        if self.level not in ("bias", "gravity", "dynamics"):
            raise ValueError(f"level must be bias, gravity or dynamics, got {self.level!r}")
        self.bias = np.zeros(6) if bias is None else np.asarray(bias, dtype=float).reshape(6)

    def external(self, raw, q, qd=None, qdd=None) -> np.ndarray:
        """The external contact wrench (sensor frame, the scene's sign convention)."""
        w = np.asarray(raw, dtype=float) - self.bias
        if self.level == "bias":
            return w
        if self.level == "gravity":
            return w - self.model.predicted_wrench(q, level="gravity")
        return w - self.model.predicted_wrench(q, qd, qdd, level="dynamics")
