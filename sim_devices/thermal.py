"""Motor winding temperature from current: a first-order thermal model.

The world simulates no temperature; emulators that report one (UR joint temperatures, DYNAMIXEL
Present Temperature) integrate ``dT/dt = (T_ambient + gain * I^2 - T) / tau`` on the world's motor
currents. The parameters are round numbers, not identified on a real motor: the reading is
plausible (warms with load, cools at rest), not a prediction.
"""
from __future__ import annotations

import math

import numpy as np


class ThermalModel:
    def __init__(self, n: int, ambient_c: float = 25.0, gain_c_per_a2: float = 2.0, tau_s: float = 600.0,
                 start_c: float | None = None) -> None:
        self.ambient = ambient_c
        self.gain = gain_c_per_a2
        self.tau = tau_s
        self.temperature = np.full(n, ambient_c + 8.0 if start_c is None else start_c)
        self._t: float | None = None

    def update(self, t: float, current) -> np.ndarray:
        """Advance to time ``t`` (s) under ``current`` (A, per motor); returns the temperatures (deg C)."""
        if self._t is not None and t > self._t:
            a = 1.0 - math.exp(-(t - self._t) / self.tau)
            target = self.ambient + self.gain * np.square(np.asarray(current, dtype=float))
            self.temperature += a * (target - self.temperature)
        self._t = t if self._t is None else max(self._t, t)
        return self.temperature
