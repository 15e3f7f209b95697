"""Contact onset and offset from the external wrench: a Mahalanobis test with hysteresis and debounce.

Without contact the compensated wrench is noise with covariance ``cov`` (the sensor's, plus what the
compensation adds), so d2 = w^T cov^-1 w follows a chi-square law with 6 degrees of freedom. Onset:
d2 above ``on`` (the chi-square quantile for a per-sample false-alarm probability ``p_false``) for
``n_on`` consecutive samples; the onset time is the first of them. Offset: d2 below ``off`` for
``n_off`` consecutive samples. ``probability`` = P(chi2_6 < d2): how unlikely this wrench is as noise.
The compensation can add its own uncertainty per sample (``update(..., model_error=u)``).

A sample whose model error alone is as large as an onset (sum_k u_k^T cov^-1 u_k above ``on``: the
arm braking hard, say) says nothing about whether a contact has ended: the inflated covariance would
call any wrench small. Such samples neither count toward an offset nor reset the count (``blind``):
a contact held through a reflex stop stays one contact instead of ending and starting again. For at
most ``max_blind_s`` at a stretch: a model whose error stays that large while the arm moves (one
identified from too little motion) would otherwise hold the contact open for good and hide every
later one (measured: `ftc demo` after 30 s of identification saw 1 of 7 contacts, one event open from
the first touch to the run's end); past it the offset is judged on the inflated covariance.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .kernels import mahalanobis2, quad_sum


def chi2_sf6(x: float) -> float:
    """Survival function of the chi-square law with 6 degrees of freedom."""
    if x <= 0:
        return 1.0
    h = 0.5 * x
    return math.exp(-h) * (1.0 + h + h * h / 2.0)


def chi2_isf6(p: float) -> float:
    """The x with chi2_sf6(x) = p (bisection; p in (0, 1))."""
    if not 0.0 < p < 1.0:
        raise ValueError("p must be in (0, 1)")
    lo, hi = 0.0, 10.0
    while chi2_sf6(hi) > p:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if chi2_sf6(mid) > p:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


@dataclass(frozen=True, slots=True)
class Detection:
    active: bool
    d2: float  # under the noise plus this sample's model error
    blind: bool  # in contact, the model error alone is as large as an onset: an offset is not judged
    probability: float
    change: str | None  # "onset", "offset" or None
    onset_t_ns: int | None  # when the current (or just ended) contact began


class ContactDetector:
    def __init__(self, cov, *, p_false: float = 1e-9, release: float = 0.25, n_on: int = 2, n_off: int = 5,
                 max_blind_s: float = 1.0) -> None:
        cov = np.asarray(cov, dtype=float)
        if cov.shape != (6, 6):
            raise ValueError("cov must be 6x6")
        self.cov = cov
        self.inv = np.linalg.inv(cov)
        self._hysteresis(chi2_isf6(p_false), release, n_on, n_off, max_blind_s)

    def _hysteresis(self, on: float, release: float, n_on: int, n_off: int, max_blind_s: float) -> None:
        """The onset threshold ``on`` (d2), the offset's ``release * on``, the debounce counts, the state."""
        self.on = on
        self.off = release * self.on
        self.n_on = n_on
        self.n_off = n_off
        self.max_blind_ns = int(max_blind_s * 1e9)
        self._blind_since: int | None = None
        self.active = False
        self._above = 0
        self._below = 0
        self._first_above: int | None = None
        self.onset_t_ns: int | None = None

    def reset(self) -> None:
        self.active = False
        self._above = self._below = 0
        self._first_above = self.onset_t_ns = self._blind_since = None

    def update(self, t_ns: int, wrench, model_error=None) -> Detection:
        """``model_error``: optional wrench-sized vectors u_k (rows) of the compensation's own
        uncertainty for this sample: covariance sum u_k u_k^T added to the noise's."""
        w = np.asarray(wrench, dtype=float)
        u = None
        if model_error is not None and len(model_error):
            u = np.atleast_2d(np.asarray(model_error, dtype=float))
            d2 = mahalanobis2(w, self.cov, u)
        else:
            d2 = float(w @ self.inv @ w)
        if not math.isfinite(d2):
            raise ValueError("wrench holds NaN or Inf")
        change, blind = self._judge(t_ns, d2, u)
        return Detection(self.active, d2, blind, 1.0 - chi2_sf6(d2), change, self.onset_t_ns)

    def _judge(self, t_ns: int, d2: float, u: np.ndarray | None,
               d2_release: float | None = None) -> tuple[str | None, bool]:
        """One sample's statistic d2 through the hysteresis: (the change, blind). ``d2_release``: in contact,
        the statistic the offset is judged on, where it differs from d2."""
        change = None
        blind = False
        if not self.active:
            if d2 > self.on:
                if self._above == 0:
                    self._first_above = t_ns
                self._above += 1
                if self._above >= self.n_on:
                    self.active = True
                    self.onset_t_ns = self._first_above
                    self._below = 0
                    self._blind_since = None
                    change = "onset"
            else:
                self._above = 0
        elif self._blinded(t_ns, u):
            blind = True  # no offset judged: the count is neither advanced nor reset
        elif (d2 if d2_release is None else d2_release) < self.off:
            self._below += 1
            if self._below >= self.n_off:
                self.active = False
                self._above = 0
                change = "offset"
        else:
            self._below = 0
        return change, blind

    def _blinded(self, t_ns: int, u: np.ndarray | None) -> bool:
        """In contact: the model error alone as large as an onset, for under ``max_blind_s`` so far."""
        if u is None or quad_sum(u, self.inv) <= self.on:
            self._blind_since = None
            return False
        if self._blind_since is None:
            self._blind_since = t_ns
        return t_ns - self._blind_since < self.max_blind_ns
