"""Re-zero: update only the bias, from windows where the arm is still and no contact is detected,
and track how the bias drifts over time.

Feed it every sample with the detector's verdict: ``rz.update(t, raw, q, qd, contact=active)``.
A window (``window_s``) of still, contact-free samples gives a new bias = mean(raw - the arm's and
payload's static load); any contact or motion discards the window being collected. The payload and
mass model are left alone: a re-zero cannot see them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ftc_hw.compensation import Compensator

from .stillness import StillnessGate


@dataclass(frozen=True)
class BiasUpdate:
    t: float  # s, mid-time of the window
    bias: np.ndarray
    change: np.ndarray  # from the previous bias
    samples: int


class ReZero:
    def __init__(self, compensator: Compensator, *, window_s: float = 0.5, gate: StillnessGate | None = None,
                 min_interval_s: float = 1.0) -> None:
        self.compensator = compensator
        scene = compensator.model.scene
        self.n_window = max(10, int(round(window_s * scene.sensor.rate_hz)))
        self.gate = gate or StillnessGate(scene)
        self.min_interval_s = min_interval_s
        self._t: list[float] = []
        self._w: list[np.ndarray] = []
        self._q: list[np.ndarray] = []
        self._qd: list[np.ndarray] = []
        self.history: list[BiasUpdate] = []
        self.rejected = 0

    def _clear(self) -> None:
        self._t, self._w, self._q, self._qd = [], [], [], []

    def update(self, t: float, raw, q, qd=None, contact: bool = False) -> BiasUpdate | None:
        """One sample (t in s). Returns the bias update when this sample completed a still window."""
        if contact:
            self._clear()
            return None
        self._t.append(float(t))
        self._w.append(np.asarray(raw, dtype=float))
        self._q.append(np.asarray(q, dtype=float))
        self._qd.append(np.zeros(len(self._q[-1])) if qd is None else np.asarray(qd, dtype=float))
        if len(self._w) < self.n_window:
            return None
        w, qs, qds = np.array(self._w), np.array(self._q), np.array(self._qd)
        ts = np.array(self._t)
        self._clear()
        if self.history and ts.mean() - self.history[-1].t < self.min_interval_s:
            return None
        report = self.gate.check(w, qs, qds)
        if not report.still:
            self.rejected += 1
            return None
        comp = self.compensator
        loads = np.mean([comp.loads(qi)[0] for qi in qs[:: max(1, len(qs) // 10)]], axis=0)
        bias = w.mean(axis=0) - loads
        update = BiasUpdate(float(ts.mean()), bias, bias - comp.bias, len(w))
        comp.bias = bias.copy()
        self.history.append(update)
        return update

    def drift_rate(self) -> np.ndarray | None:
        """Bias drift (N/s, N m/s per axis) fitted over the updates so far (None before two)."""
        if len(self.history) < 2:
            return None
        t = np.array([u.t for u in self.history])
        b = np.array([u.bias for u in self.history])
        tc = t - t.mean()
        den = float(tc @ tc)
        return np.zeros(6) if den == 0 else (tc @ (b - b.mean(axis=0))) / den
