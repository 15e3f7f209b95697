"""The simulated F/T sensor: bias, drift, per-axis Gaussian noise, quantization, saturation."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ftc_hw.scene import SensorSpec


@dataclass(frozen=True)
class SensorReading:
    wrench: np.ndarray  # what the device reports (sensor frame, scene sign convention), N and N m
    saturated: np.ndarray  # per-axis bool


class FTSensorModel:
    def __init__(self, spec: SensorSpec, rng: np.random.Generator, noise: bool = True) -> None:
        self.spec = spec
        self.rng = rng
        self.noise = noise

    def read(self, clean: np.ndarray, t: float) -> SensorReading:
        s = self.spec
        w = clean + s.bias + s.drift_per_s * t
        if self.noise:
            w = w + self.rng.normal(0.0, 1.0, 6) * s.noise_std
        q = s.quantization
        if np.any(q > 0):
            lsb = np.where(q > 0, q, 1.0)
            w = np.where(q > 0, np.round(w / lsb) * lsb, w)
        saturated = np.abs(w) >= s.range
        return SensorReading(np.clip(w, -s.range, s.range), saturated)
