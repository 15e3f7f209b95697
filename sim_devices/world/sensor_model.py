"""The simulated F/T sensor: gain and crosstalk, bias, drift (linear and thermal), white and coloured
noise, quantization, saturation."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ftc_hw.scene import SensorSpec
from ftc_hw.scene.world_spec import IDEAL, WorldSpec


@dataclass(frozen=True)
class SensorReading:
    wrench: np.ndarray  # what the device reports (sensor frame, scene sign convention), N and N m
    saturated: np.ndarray  # per-axis bool


class FTSensorModel:
    """``reading = gain @ true + bias + drift t + thermal(t) + coloured + white``, quantized and clipped.
    The gain, coloured noise and thermal drift are the world's (``[world]``); the rest the scene's sensor."""

    def __init__(self, spec: SensorSpec, rng: np.random.Generator, noise: bool = True,
                 world: WorldSpec = IDEAL) -> None:
        self.spec = spec
        self.rng = rng
        self.noise = noise
        self.gain = None if np.array_equal(world.sensor_gain, np.eye(6)) else np.asarray(world.sensor_gain)
        self.thermal = (np.asarray(world.temperature_drift) * world.temperature_rise_K
                        if world.temperature_rise_K and np.any(world.temperature_drift) else None)
        self.thermal_tau = world.temperature_tau_s
        self.coloured_std = np.asarray(world.coloured_noise_std) if np.any(world.coloured_noise_std) else None
        self.coloured_tau = world.coloured_noise_tau_s
        self._coloured = np.zeros(6)
        self._t_last: float | None = None
        # per read: the quantized axes' LSB (None: no axis is) and the clip's lower limit
        quantized = np.asarray(spec.quantization) > 0
        self._lsb = np.where(quantized, spec.quantization, 1.0) if np.any(quantized) else None
        self._quantized = None if np.all(quantized) else quantized  # None: every axis
        self._low = -np.asarray(spec.range)

    def read(self, clean: np.ndarray, t: float) -> SensorReading:
        s = self.spec
        w = clean if self.gain is None else self.gain @ clean
        w = w + s.bias + s.drift_per_s * t
        if self.thermal is not None:  # the sensor warming from the run's start
            w = w + self.thermal * (1.0 - math.exp(-t / self.thermal_tau))
        if self.noise:
            w = w + self.rng.normal(0.0, 1.0, 6) * s.noise_std
            if self.coloured_std is not None:
                w = w + self._coloured_step(t)
        if self._lsb is not None:
            rounded = np.round(w / self._lsb) * self._lsb
            w = rounded if self._quantized is None else np.where(self._quantized, rounded, w)
        saturated = np.abs(w) >= s.range
        return SensorReading(np.minimum(np.maximum(w, self._low), s.range), saturated)  # np.clip's values

    def _coloured_step(self, t: float) -> np.ndarray:
        """First-order Gauss-Markov noise with the world's stationary std and correlation time."""
        if self._t_last is None:
            self._coloured = self.rng.normal(0.0, 1.0, 6) * self.coloured_std
        else:
            a = math.exp(-max(t - self._t_last, 0.0) / self.coloured_tau)
            fresh = self.rng.normal(0.0, 1.0, 6) * self.coloured_std
            self._coloured = a * self._coloured + math.sqrt(1.0 - a * a) * fresh
        self._t_last = t
        return self._coloured
