"""Identification from contact-free motion: the arm's inertial parameters and the sensor's linear
errors (gain, crosstalk, mount pose) from the F/T readings and the joint state, in one linear fit.

    reading - nominal(q, qd, qdd) = bias + Y(q, qd, qdd) dpi + dG nominal(q, qd, qdd) + noise

``Y`` is the base-wrench regressor of the moving links (:mod:`ftc_hw.model.inertials`), ``dpi`` their
parameter corrections, ``dG`` the 6 x 6 linear error of the sensor (a small mount rotation and offset
are such a map too). The fit is Bayesian least squares about the model: each parameter has a prior
standard deviation (``Priors``), so what the motion cannot tell stays at the model's value and keeps
its prior uncertainty; the verdict names those directions. Signals are low-passed forward and back
(no lag) and thinned to about independent samples before the fit.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import mujoco
import numpy as np

from ..model import ArmModel
from ..model.build import descends, moves
from ..model.inertials import N_PARAMS, PARAM_LABELS, body_params, inertia_at_com, model_rows

HUBER_K = 1.345
MIN_SEGMENT_SAMPLES = 5  # thinned samples: a stretch shorter than 8 x this many raw ones is left out
MIN_SAMPLES = 200
SMOOTH_S = 0.05  # s: the moving-average window, applied twice (a triangle 0.1 s wide, -3 dB near 9 Hz)
TOLD = 0.5  # a direction is told by the data when its posterior std is below this fraction of its prior's
# The contact's wrench has the gain undone only where the data told at least this many of its 36
# directions. Measured (typical world, 5 draws, 2 min of motion): ur5e's base sensor under a 200 N arm
# tells 33-35 of them from the planned excitation and 19-21 from the ordinary sweep, and undoing those
# took the sweep-identified localization from 5.3 / 19.2 to 3.3 / 12.1 mm (median / p95); dxl-arm's
# 6 N arm on a 300 N sensor tells 10-11, and undoing them took the p95 from 9.6 to 15.7 mm.
MIN_TOLD_GAIN_DIRECTIONS = 18


class IdentificationError(ValueError):
    """Not enough free motion to identify anything."""


@dataclass(frozen=True)
class Priors:
    """Prior standard deviations: how far the true arm may plausibly be from the model."""

    mass_rel: float = 0.10
    com_m: float = 0.01
    inertia_rel: float = 0.30
    gain: float = 2.0  # each entry of dG, in units of the scene's sensor accuracy (range-scaled off the diagonal)
    bias: float = 1e3  # N, N m: unknown


@dataclass
class MotionData:
    """Contact-free motion: F/T readings and the joint state at their times."""

    t: np.ndarray  # (N,) s
    wrench: np.ndarray  # (N, 6) raw readings
    q: np.ndarray  # (N, n) rad
    qd: np.ndarray  # (N, n) rad/s
    current: np.ndarray | None = None  # (N, n) A, the motor currents (joint friction needs them)


@dataclass
class FreeMotionFit:
    bodies: list[str]
    bias: np.ndarray  # (6,)
    delta_pi: np.ndarray  # (len(bodies), 10)
    gain: np.ndarray  # (6, 6): reading = gain @ true + bias
    cov: np.ndarray  # posterior covariance of [bias, dpi, dG] (scaled back to SI)
    labels: list[str]
    prior_std: np.ndarray
    residual_rms: np.ndarray  # (6,) after the fit, of the thinned samples
    residual_rms_before: np.ndarray  # (6,) the nominal model's (its mean removed)
    samples: int
    t: np.ndarray  # (samples,) s: the thinned samples' times (the recording's clock)
    residuals: np.ndarray  # (samples, 6): reading minus the identified model (N, N m)
    residuals_before: np.ndarray  # (samples, 6): minus the nominal model, its mean removed
    untold: list[str] = field(default_factory=list)  # the directions the data could not tell
    verdict: str = "good"
    reasons: list[str] = field(default_factory=list)

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.diag(self.cov))

    def told_gain(self, min_directions: int = MIN_TOLD_GAIN_DIRECTIONS) -> np.ndarray:
        """The gain to undo on a contact's wrench: the estimate's part in the directions the data told
        (posterior std below ``TOLD`` of the prior's, in the prior's units), the model's value (none)
        across the rest; the identity when fewer than ``min_directions`` were told (a gain told in a few
        directions leans on what the fit could not separate from it: MIN_TOLD_GAIN_DIRECTIONS)."""
        if len(self.labels) == 6 + self.delta_pi.size:  # no gain fitted
            return np.eye(6)
        prior = self.prior_std[-36:]
        lam, vec = np.linalg.eigh(self.cov[-36:, -36:] / np.outer(prior, prior))
        told = vec[:, lam < TOLD**2]
        if told.shape[1] < min_directions:
            return np.eye(6)
        d_gain = (self.gain - np.eye(6)).reshape(-1) / prior
        return np.eye(6) + (prior * (told @ (told.T @ d_gain))).reshape(6, 6)

    @property
    def estimate(self) -> np.ndarray:
        """[bias, dpi per body, dG (if fitted)]: in the order of ``labels``, about the model (prior mean 0
        but for the bias)."""
        parts = [self.bias, self.delta_pi.reshape(-1)]
        if len(self.labels) > 6 + self.delta_pi.size:
            parts.append((self.gain - np.eye(6)).reshape(-1))
        return np.concatenate(parts)


def smooth(x: np.ndarray, n: int) -> np.ndarray:
    """Zero-phase low pass along axis 0: a centred moving average of ``n`` samples, twice."""
    if n <= 1:
        return x.copy()
    kernel = np.ones(n) / n
    pad = n
    out = np.pad(x, ((pad, pad), (0, 0)), mode="edge")
    for _ in range(2):
        out = np.stack([np.convolve(out[:, j], kernel, mode="same") for j in range(out.shape[1])], axis=1)
    return out[pad:-pad]


def prepare(data: MotionData, smooth_s: float = SMOOTH_S, with_current: bool = False) -> tuple[np.ndarray, ...]:
    """(t, wrench, q, qd, qdd[, current]): low-passed, qdd differentiated, thinned to one sample per
    window."""
    dt = float(np.median(np.diff(data.t)))
    n = max(1, int(round(smooth_s / dt)))
    w, q, qd = smooth(data.wrench, n), smooth(data.q, n), smooth(data.qd, n)
    qdd = np.gradient(qd, data.t, axis=0)
    keep = slice(2 * n, len(data.t) - 2 * n, n)  # the ends see the padding
    out = (data.t[keep], w[keep], q[keep], qd[keep], qdd[keep])
    if with_current:
        out += (smooth(data.current, n)[keep],)
    return out


class FreeMotionIdentifier:
    def __init__(self, arm: ArmModel, priors: Priors | None = None, gain: bool = True) -> None:
        self.arm = arm
        self.priors = priors or Priors()
        self.with_gain = gain
        m = arm.model
        # the moving bodies the sensor carries that have inertia to identify (a flange sensor's own
        # tool-side body is massless: nothing of it can be told)
        self.body_ids = [b for b in range(1, m.nbody)
                         if descends(m, b, arm.sensor_body) and moves(m, b) and m.body_mass[b] > 0]
        self.bodies = [m.body(b).name for b in self.body_ids]
        self.pi0 = np.concatenate([body_params(m, b) for b in self.body_ids])
        self._data = mujoco.MjData(m)
        self.labels = ([f"bias_{a}" for a in ("fx", "fy", "fz", "tx", "ty", "tz")]
                       + [f"{b}.{p}" for b in self.bodies for p in PARAM_LABELS]
                       + ([f"gain[{i},{j}]" for i in range(6) for j in range(6)] if gain else []))
        self.prior_sqrt = self._prior()
        self.prior_std = np.sqrt(np.sum(self.prior_sqrt**2, axis=1))

    def _prior(self) -> np.ndarray:
        """A square root ``L`` of the prior covariance (``x = L z``, ``z`` standard normal). Each body's
        prior is independent in (mass, first moments, inertia about the centre of mass); carried to
        the regressor's inertia about the body origin, moving the centre of mass moves that inertia too,
        so the posterior keeps the inertia about the centre of mass near the model's."""
        p = self.priors
        blocks = [np.eye(6) * p.bias]
        blocks += [body_prior(self.pi0[k * N_PARAMS:(k + 1) * N_PARAMS], p) for k in range(len(self.bodies))]
        if self.with_gain:
            full = np.asarray(self.arm.scene.sensor.range, dtype=float)
            scale = p.gain * max(self.arm.scene.sensor.accuracy, 1e-4) * full[:, None] / full[None, :]
            blocks.append(np.diag(scale.reshape(-1)))
        return block_diagonal(blocks)

    def rows(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(A, nominal): the fit's 6 x P rows and the model's reading (no bias) at one state."""
        a, nominal = model_rows(self.arm, self._data, self.body_ids, q, qd, qdd, self.with_gain)
        return np.hstack([np.eye(6), a]), nominal

    def fit(self, data: MotionData | Sequence[MotionData]) -> FreeMotionFit:
        """Fit one stretch of free motion, or several (each low-passed on its own: gaps between them,
        contacts cut out, are never smoothed across)."""
        rows, resid, times = [], [], []
        for segment in [data] if isinstance(data, MotionData) else data:
            if len(segment.t) < 8 * MIN_SEGMENT_SAMPLES:
                continue
            t, w, q, qd, qdd = prepare(segment)
            times.append(t)
            for k in range(len(w)):
                a, nominal = self.rows(q[k], qd[k], qdd[k])
                rows.append(a)
                resid.append(w[k] - nominal)
        if len(rows) < MIN_SAMPLES:
            raise IdentificationError(f"{len(rows)} usable samples of free motion (at least {MIN_SAMPLES} needed: "
                                      f"{MIN_SAMPLES * SMOOTH_S:g} s)")
        a = np.vstack(rows)
        y = np.concatenate(resid)
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(y))):
            raise IdentificationError("the motion data hold NaN or Inf (repeated time stamps, a broken frame?)")
        before = np.array(resid) - np.mean(resid, axis=0)
        x, cov, r = self._irls(a, y)
        return self._result(x, cov, r, before, np.concatenate(times))

    def _irls(self, a: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each axis weighed by its robust residual scale, each sample-axis by Huber's weight: a
        contact the recording did not mark, a glitch, weigh little."""
        scale = np.sqrt(np.diag(self.arm.scene.sensor.noise_cov))
        huber = np.ones_like(y)
        x = cov = r = None
        for _ in range(4):
            weights = np.tile(1.0 / scale, len(y) // 6) * np.sqrt(huber)
            x, cov = bayes(a * weights[:, None], y * weights, self.prior_sqrt)
            r = (y - a @ x).reshape(-1, 6)
            scale = np.maximum(1.4826 * np.median(np.abs(r - np.median(r, axis=0)), axis=0), scale * 0.1)
            u = np.abs(r / scale).reshape(-1)
            huber = np.where(u <= HUBER_K, 1.0, HUBER_K / np.maximum(u, 1e-12))
        return x, cov, r

    def _result(self, x, cov, r, before, t) -> FreeMotionFit:
        nb = len(self.bodies)
        dpi = x[6:6 + N_PARAMS * nb].reshape(nb, N_PARAMS)
        gain = np.eye(6) + (x[6 + N_PARAMS * nb:].reshape(6, 6) if self.with_gain else 0.0)
        fit = FreeMotionFit(self.bodies, x[:6].copy(), dpi, gain, cov, self.labels, self.prior_std,
                            _rms(r), _rms(before), len(t), t, r, before)
        ratio = np.sqrt(np.diag(cov)) / self.prior_std
        fit.untold = [lab for lab, v in zip(self.labels, ratio, strict=True) if v > TOLD and not lab.startswith("bias")]
        if fit.untold:
            fit.verdict = "poorly_excited"
            fit.reasons.append(f"{len(fit.untold)} of {len(self.labels) - 6} parameters not told apart by this motion "
                               f"(posterior std above {TOLD:g} x prior): they stay at the model's values")
        return fit


def body_prior(pi: np.ndarray, p: Priors) -> np.ndarray:
    """A square root (10 x 10) of one body's prior covariance about its parameters ``pi``: independent
    in (mass, first moments, inertia about the centre of mass), carried to the inertia about the origin."""
    mass, h = pi[0], pi[1:4]
    i_c = inertia_at_com(pi)
    std = np.array([p.mass_rel * mass, *([mass * p.com_m + p.mass_rel * np.linalg.norm(h)] * 3),
                    *([p.inertia_rel * max(np.max(np.linalg.eigvalsh(i_c)), 1e-6)] * 6)])
    return _com_to_origin_jacobian(mass, h) @ np.diag(std)


def block_diagonal(blocks: Sequence[np.ndarray]) -> np.ndarray:
    out = np.zeros((sum(b.shape[0] for b in blocks),) * 2)
    k = 0
    for b in blocks:
        out[k:k + b.shape[0], k:k + b.shape[0]] = b
        k += b.shape[0]
    return out


def _rms(r: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean(r * r, axis=0))


def bayes(a: np.ndarray, y: np.ndarray, prior_sqrt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Minimise |y - a x|^2 + |z|^2 over x = L z (L = ``prior_sqrt``): the estimate and its posterior
    covariance."""
    b = a @ prior_sqrt
    u, s, vt = np.linalg.svd(b, full_matrices=False)
    z = vt.T @ (s / (s * s + 1.0) * (u.T @ y))
    cov_z = vt.T @ np.diag(1.0 / (s * s + 1.0)) @ vt
    return prior_sqrt @ z, prior_sqrt @ cov_z @ prior_sqrt.T


_SYM = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


def _com_to_origin_jacobian(mass: float, h: np.ndarray) -> np.ndarray:
    """d(mass, h, I_origin) / d(mass, h, I_com) (10 x 10), from I_o = I_c + (|h|^2 1 - h h^T) / m."""
    j = np.eye(N_PARAMS)
    shift = (h @ h * np.eye(3) - np.outer(h, h))
    for r, (a, b) in enumerate(_SYM):
        j[4 + r, 0] = -shift[a, b] / mass**2
        for c in range(3):
            d_shift = 2 * h[c] * (a == b) - ((c == a) * h[b] + (c == b) * h[a])
            j[4 + r, 1 + c] = d_shift / mass
    return j
