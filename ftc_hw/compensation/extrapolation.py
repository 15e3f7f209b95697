"""The joint state ahead of the newest joint sample, and what that guess may get wrong.

An F/T frame judged at once, before the joint stream has passed its time, gets the joint state
extrapolated from the newest two joint samples at constant acceleration ``a = (qd0 - qd1) / (t0 - t1)``:

    q = q0 + qd0 dt + a dt^2 / 2,   qd = qd0 + a dt,   qdd = a,   dt = t - t0

Its error is the acceleration's departure from ``a``: a joint's acceleration error ``s`` (rad/s^2) moves
q by ``s dt^2 / 2``, qd by ``s dt`` and qdd by ``s``, so in the compensated wrench it is the rows
``s dW/dq dt^2/2``, ``s dW/dqd dt`` and ``s dW/dqdd`` of that joint (:func:`extrapolation_rows`), the model's
sensitivities taken at the state (:func:`wrench_sensitivities`).

``s`` is identified from the joint stream itself (:class:`AccelerationSpread`): at each joint sample, the
velocity the previous two samples foretold against the one measured, per second of the span, is how far
the acceleration strayed from constant over one joint period; a peak of it that fades slowly (the arm's
program comes back to its reversals and stops) is the spread, times a margin. It is identified once the arm
has been seen moving for a while (``ready``): a still arm's first acceleration, its start, would read as a
contact (measured: ur5e-netft at 7 kHz, the sweep's start 18 ms in, one provisional onset unconfirmed).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..model import ArmModel
from ..scene import CompensationLevel

FD_STEP_Q = 1e-5  # rad: the sensitivities' finite step (the wrench is smooth in q; 1e-5 rad keeps
FD_STEP_QD = 1e-4  # rad/s   the rounding of MuJoCo's doubles far below the sensor's noise)


class Extrapolated(NamedTuple):
    """The joint state (n,) at a time from the newest samples: q rad, qd rad/s, qdd rad/s^2 (the samples'
    constant acceleration); ``ahead_s``: how far past the newest sample (0: at or before it)."""

    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    ahead_s: float


def extrapolate(t_ns: int, newest: tuple[int, np.ndarray, np.ndarray],
                previous: tuple[int, np.ndarray, np.ndarray]) -> Extrapolated:
    """The state at ``t_ns`` from the newest joint sample ``(t0_ns, q0, qd0)`` and the one before it (same form)
    at their constant acceleration. ``t_ns`` before ``t0`` (the stream passed it) steps back along the same
    parabola, ``ahead_s`` 0."""
    t0, q0, qd0 = newest
    t1, _, qd1 = previous
    if t0 <= t1:
        raise ValueError("the newest joint sample must be later than the previous one")
    a = (qd0 - qd1) / ((t0 - t1) * 1e-9)
    dt = (t_ns - t0) * 1e-9
    return Extrapolated(q0 + qd0 * dt + a * (0.5 * dt * dt), qd0 + a * dt, a, max(dt, 0.0))


class Sensitivities(NamedTuple):
    """d(compensated wrench)/d(q), /d(qd), /d(qdd), each (6, n), sensor frame, at one state."""

    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray


def wrench_sensitivities(model: ArmModel, level: CompensationLevel, q: np.ndarray, qd: np.ndarray,
                         qdd: np.ndarray) -> Sensitivities:
    """The arm's own wrench on the sensor, differentiated at (q, qd, qdd) (``level`` as the compensation's):
    forward differences in q and qd (2n inverse dynamics), the exact linear map in qdd. Leaves ``model``'s
    data at a perturbed state: call it on a model of its own (:meth:`ArmModel.twin`)."""
    n = q.size
    base = model.arm_loads(q, qd, qdd, level)[0]
    g = model.wrench_qdd_jacobian() if level == "dynamics" else np.zeros((6, n))
    dq, dqd = np.zeros((6, n)), np.zeros((6, n))
    for k in range(n):
        x = q.copy()
        x[k] += FD_STEP_Q
        dq[:, k] = (model.arm_loads(x, qd, qdd, level)[0] - base) / FD_STEP_Q
        if level == "dynamics":
            v = qd.copy()
            v[k] += FD_STEP_QD
            dqd[:, k] = (model.arm_loads(q, v, qdd, level)[0] - base) / FD_STEP_QD
    return Sensitivities(dq, dqd, g)


def extrapolation_rows(sens: Sensitivities, spread: np.ndarray, ahead_s: float, period_s: float) -> np.ndarray:
    """Covariance rows (n or 3n, 6) of the wrench error of a state extrapolated ``ahead_s`` past the newest joint
    sample with a per-joint acceleration error ``spread`` (n,) rad/s^2 (over one joint period, ``period_s``): per
    joint its qdd error's row and, ahead of the sample, its q and qd errors' rows. Apart, not added in one row:
    the acceleration does not stray by one constant over the span, so the three need not cancel (one row would
    let dW/dqd h cancel dW/dqdd). Past half a period the error grows on as the acceleration's drift does (the
    samples' acceleration is their span's middle's; a drift's innovation is one period's worth of it):
    ``spread * max(1, 1/2 + h / period)``."""
    h = max(float(ahead_s), 0.0)
    s = spread * max(1.0, 0.5 + h / period_s) if period_s > 0.0 else spread
    rows = (sens.qdd * s).T
    if h > 0.0:
        rows = np.vstack([rows, (sens.qd * (s * h)).T, (sens.q * (s * (0.5 * h * h))).T])
    return np.ascontiguousarray(rows)


class AccelerationSpread:
    """Per joint, how far the acceleration strays from constant over a joint period, identified from the joint
    stream (module docstring). ``observe`` each joint sample (its time ns and qd rad/s); ``spread`` (n,)
    rad/s^2: ``margin`` times the peak innovation, fading with time constant ``memory_s``, never below ``floor``.
    Samples out of order are ignored; a span over ``max_span_s`` (a loss) restarts the prediction."""

    def __init__(self, n: int, *, margin: float = 2.0, floor: float = 0.05, memory_s: float = 300.0,
                 max_span_s: float = 0.05, moving_s: float = 1.0, moving_qd: float = 0.05) -> None:
        self.margin, self.floor, self.memory_s, self.max_span_s = margin, floor, memory_s, max_span_s
        self.moving_s, self.moving_qd = moving_s, moving_qd
        self.moved_s = 0.0  # how long the arm has been seen moving (any joint over moving_qd rad/s)
        self._peak = np.zeros(n)
        self._t_peak: int | None = None
        self._last: tuple[int, np.ndarray] | None = None
        self._a: np.ndarray | None = None
        self.samples = 0  # innovations measured

    def observe(self, t_ns: int, qd: np.ndarray) -> None:
        last = self._last
        qd = np.asarray(qd, dtype=float)
        if last is not None and t_ns <= last[0]:
            return
        self._last = (t_ns, qd)
        if last is None:
            return
        dt = (t_ns - last[0]) * 1e-9
        if dt > self.max_span_s:
            self._a = None
            return
        a_prev = self._a
        self._a = (qd - last[1]) / dt
        if a_prev is None:
            return
        innovation = np.abs(qd - last[1] - a_prev * dt) / dt
        if np.abs(qd).max() > self.moving_qd:
            self.moved_s += dt
        self._fade(t_ns)
        self._peak = np.maximum(self._peak, innovation)  # a new array: a reader never sees a half-made one
        self.samples += 1

    def _fade(self, t_ns: int) -> None:
        if self._t_peak is not None:
            self._peak = self._peak * math.exp(-(t_ns - self._t_peak) * 1e-9 / self.memory_s)
        self._t_peak = t_ns

    @property
    def ready(self) -> bool:
        """The spread is identified: the arm was seen moving for ``moving_s`` (its start among it). Before, a
        still arm's spread (the floor) would take its first acceleration for a contact."""
        return self.moved_s >= self.moving_s

    @property
    def spread(self) -> np.ndarray:
        return np.maximum(self.margin * self._peak, self.floor)
