"""Joint-space reference trajectories for the world's joint controller: (q, qd, qdd) at time t."""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np


class Trajectory(ABC):
    @abstractmethod
    def reference(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Desired (q rad, qd rad/s, qdd rad/s^2) at time t (s)."""


@dataclass(frozen=True)
class Hold(Trajectory):
    q: np.ndarray

    def reference(self, t: float):
        q = np.asarray(self.q)
        return q.copy(), np.zeros(q.shape, q.dtype), np.zeros(q.shape, q.dtype)  # zeros_like costs 5 times more


@dataclass(frozen=True)
class Glide(Trajectory):
    """A streamed setpoint with its velocity: q + qd t up to ``horizon_s``, then held there. The next
    setpoint of the stream replaces it (a servo's velocity feed-forward); a stream that ends stops
    within the horizon."""

    q: np.ndarray
    qd: np.ndarray
    horizon_s: float

    def reference(self, t: float):
        if t >= self.horizon_s:
            z = np.zeros(self.q.shape)
            return self.q + self.qd * self.horizon_s, z, z.copy()
        return self.q + self.qd * t, self.qd.copy(), np.zeros(self.q.shape)


@dataclass(frozen=True)
class Sinusoid(Trajectory):
    """q(t) = centre + amplitude sin(2 pi f t + phase), per joint (amplitude 0 holds the joint).

    The default phase -pi/2 starts at rest (qd(0) = 0) at centre - amplitude; the arm holds there
    for ``start_s`` first (time to tare the sensor)."""

    centre: np.ndarray
    amplitude: np.ndarray
    frequency_hz: float
    phase: float = -np.pi / 2
    start_s: float = 0.0

    def reference(self, t: float):
        w = 2.0 * np.pi * self.frequency_hz
        if t < self.start_s:  # at rest: no velocity or acceleration feed-forward
            z = np.zeros_like(self.centre)
            return self.centre + self.amplitude * np.sin(self.phase), z, z.copy()
        t -= self.start_s
        s, c = np.sin(w * t + self.phase), np.cos(w * t + self.phase)
        return self.centre + self.amplitude * s, self.amplitude * w * c, -self.amplitude * w * w * s


@dataclass(frozen=True)
class PointToPoint(Trajectory):
    """Minimum-jerk moves through waypoints, each move ``move_s`` long followed by a ``hold_s`` rest."""

    waypoints: np.ndarray  # (k, n)
    move_s: float
    hold_s: float

    @property
    def duration(self) -> float:
        return (len(self.waypoints) - 1) * (self.move_s + self.hold_s) + self.hold_s

    def reference(self, t: float):
        wp = self.waypoints
        seg = self.move_s + self.hold_s
        t = max(t - self.hold_s, 0.0)  # rest at the first waypoint first
        i = int(t // seg)
        if i >= len(wp) - 1:
            z = np.zeros(wp.shape[1])
            return wp[-1].copy(), z, z.copy()
        tau = min((t - i * seg) / self.move_s, 1.0)
        d = wp[i + 1] - wp[i]
        s = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
        ds = (30 * tau**2 - 60 * tau**3 + 30 * tau**4) / self.move_s if tau < 1 else 0.0
        dds = (60 * tau - 180 * tau**2 + 120 * tau**3) / self.move_s**2 if tau < 1 else 0.0
        return wp[i] + s * d, ds * d, dds * d
