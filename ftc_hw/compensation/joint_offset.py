"""The joint torque sensors' offsets tracked while the arm is clearly free of contact: what identification
(or the tare at rest) left of them and what they drift by afterwards (with the windings' temperature:
docs/reality.md), so that neither reads as a contact.

Haddadin, De Luca & Albu-Schaeffer (T-RO 2017, sec. IV) build the momentum observer on the link-side
torque sensors' ``tau_J``, whose offset passes the observer unattenuated: r settles at minus the offset's
error. The tracker is a slow integral loop around the observer, run only on samples it trusts to be
contact-free:

    offset += clip(-<r> dt / T, +-max_rate dt),   |offset - the identified one| <= max_offset

(``T`` the averaging time, far longer than the observer's lag 1/K, so the loop is the observer's with a
slow zero added; ``<r>`` r averaged over the trusted samples of the last ``correlation_s``: the slew
limit clips a per-sample step whose noise is as large as the limit itself, which biases the mean step
low: measured, a drift at 0.75 of the limit, 100 Hz samples: the correction lagged by 78 s of drift in
place of T's 20 s). Gated: the detector not in contact, none ended within ``settle_s``, and the statistic
below ``gate`` x its onset threshold.

What it may absorb of a push: the loop follows a change at most at ``max_rate`` (above the fastest drift
the sensors' temperature gives) and only while r stays below ``sqrt(gate)`` of the threshold, where the
gate shuts it. A push whose torque rises faster than ``max_rate`` is left in r less at most ``max_rate``
x its rise time (and the gate stops even that at half the threshold); one rising slower than ``max_rate``
(on a 87 N m sensor 4.4 mN m / s: a tenth of a newton metre in 23 s) is taken for a drift, up to
``max_offset``: the trade every offset estimate on contact-free samples makes (a drift and a push that
slow look the same to the joint torques).

The tracked offset's uncertainty joins the residual's covariance (per joint, variance ``var``): while
tracking it relaxes (time constant T / 2) toward ``s^2 tau / (2 T) + (rho T)^2``, the averaging's noise
(s^2 the free residual's measured variance, ``tau`` its correlation time) and the loop's lag behind a drift
at the prior rate ``rho``; while not tracking (in contact, or the statistic high) its standard deviation
grows by ``rho`` each second. Not the rate the correction is seen to move at: a slowly rising push moves
it too, and would widen the covariance that is to reveal it (measured on this module's test, 20 N rising
over 120 s: its onset 33 % later than without tracking, 13 % with ``rho``). A drift faster than ``rho``
lags by up to ``max_rate`` x T, outside the covariance (panda draw 1's joint 4: 16 mN m against its free
residual's 49 mN m).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

MAX_STEP_S = 0.05  # a longer interval between samples (a gap, the observer restarted) is not tracked over


@dataclass(frozen=True)
class OffsetTracking:
    """How the joint torque sensors' offsets are tracked (see the module's notes). ``enabled`` False: the
    identified (or tared) offsets stay as they are. Rates and bounds are relative to each sensor's range
    (``[joint_torque] range``).

    - ``time_constant_s``: T, the loop's averaging time (ESTIMATE: 10 s, 1500 observer lags at K = 150/s:
      the free residual's model errors, which change along the motion over seconds, average out; its lag
      behind the fastest drift measured below, 1.6 mN m / s, 16 mN m);
    - ``gate``: track only while the statistic is below this share of its onset threshold (the detector's
      release level: the residual at half the threshold's magnitude);
    - ``settle_s``: none within this long after a contact's end (the observer's lag and the contact's tail);
    - ``drift_rel_per_s``: rho, 1 sigma of an offset's drift rate (ESTIMATE: the typical world's 0.02 % of
      range per K, docs/reality.md, times a winding warming by 20 K over its 900 s time constant: 4.4e-6
      / s, 0.38 mN m / s on a 87 N m sensor; Franka publishes no drift figure);
    - ``max_rate_rel_per_s``: the loop's slew limit (ESTIMATE: 5e-5 / s, 4.4 mN m / s on a 87 N m sensor:
      the fastest drift measured in the bench's typical world, panda draw 1's joint 4, 1.6 mN m / s
      (-0.0096 N m / K while its winding warmed by 0.17 K / s), with margin);
    - ``max_offset_rel``: the largest correction (ESTIMATE: 2 % of range: that joint's drift over the 50 K
      its winding warmed by in the bench's 5 minutes was 0.55 % of range, and still rising; the typical
      world's offsets themselves, +-0.2 %, are identification's);
    - ``correlation_s``: tau, how long the free residual's slow errors (the model's, along the motion)
      stay correlated (ESTIMATE: a second: the arm's motions take seconds)."""

    enabled: bool = True
    time_constant_s: float = 10.0
    gate: float = 0.25
    settle_s: float = 1.0
    drift_rel_per_s: float = 4.4e-6
    max_rate_rel_per_s: float = 5e-5
    max_offset_rel: float = 0.02
    correlation_s: float = 1.0

    def __post_init__(self) -> None:
        if not (self.time_constant_s > 0 and 0 < self.gate <= 1 and self.settle_s >= 0 and self.drift_rel_per_s >= 0
                and self.max_rate_rel_per_s >= 0 and self.max_offset_rel >= 0 and self.correlation_s >= 0):
            raise ValueError("offset tracking: time_constant_s > 0, 0 < gate <= 1, the rest >= 0")


class OffsetTracker:
    """The tracked correction of the joint torque sensors' offsets (n,) N m and its variance (see the
    module's notes). ``sensor_range`` (n,) N m. Not thread-safe: one per pipeline."""

    def __init__(self, settings: OffsetTracking, sensor_range) -> None:
        rng = np.abs(np.asarray(sensor_range, dtype=float))
        self.settings = s = settings
        self.n = rng.size
        self.max_rate = s.max_rate_rel_per_s * rng
        self.max_offset = s.max_offset_rel * rng
        self.drift = s.drift_rel_per_s * rng
        self.correction = np.zeros(self.n)  # N m, added to the offset taken off the sensors' reading
        self.var = np.zeros(self.n)  # N^2 m^2: the correction's error variance, added to r's covariance
        self.tracked_s = 0.0  # seconds of samples tracked so far
        self._spread = np.zeros(self.n)  # the free residual's running mean square
        self._mean = np.zeros(self.n)  # <r>: the free residual's mean over the last correlation_s
        self._std = np.zeros(self.n)  # sqrt(var), kept to grow it linearly while not tracking
        self._last_ns: int | None = None
        self._quiet_from_ns = 0  # no tracking before (a contact's end + settle_s)

    def reset(self) -> None:
        """Forget the correction (a fresh tare or identification set the offsets)."""
        self.correction[:] = 0.0
        self.var[:] = 0.0
        self._std[:] = 0.0
        self._spread[:] = 0.0
        self._mean[:] = 0.0
        self.tracked_s = 0.0
        self._last_ns = None

    def observe(self, t_ns: int, r: np.ndarray, *, free: bool, statistic_ratio: float) -> bool:
        """One sample's residual r (n,) N m after the detector judged it: ``free`` no contact open,
        ``statistic_ratio`` its statistic over the onset threshold. True when the correction moved."""
        dt = 0.0 if self._last_ns is None else max(0.0, (t_ns - self._last_ns) * 1e-9)
        self._last_ns = t_ns
        if not free:
            self._quiet_from_ns = t_ns + int(self.settings.settle_s * 1e9)
        if not self.settings.enabled or dt == 0.0:
            return False
        if (not free or t_ns < self._quiet_from_ns or not statistic_ratio < self.settings.gate
                or dt > MAX_STEP_S):
            self._std += self.drift * dt
            self.var = self._std**2
            return False
        self._track(np.asarray(r, dtype=float), dt)
        return True

    def _track(self, r: np.ndarray, dt: float) -> None:
        s = self.settings
        t = s.time_constant_s
        c = math.exp(-dt / s.correlation_s) if s.correlation_s > 0 else 0.0
        self._mean = c * self._mean + (1.0 - c) * r
        step = np.clip(-self._mean * (dt / t), -self.max_rate * dt, self.max_rate * dt)
        self.correction = np.clip(self.correction + step, -self.max_offset, self.max_offset)
        self.tracked_s += dt
        a = math.exp(-dt / t)
        self._spread = a * self._spread + (1.0 - a) * r * r
        # the spread's own start-up: its mean over what was tracked so far
        spread = self._spread / max(1.0 - math.exp(-self.tracked_s / t), 1e-12)
        steady = spread * s.correlation_s / (2.0 * t) + (self.drift * t) ** 2
        b = math.exp(-2.0 * dt / t)
        self.var = b * self.var + (1.0 - b) * steady
        self._std = np.sqrt(self.var)
