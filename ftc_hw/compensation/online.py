"""Online refinement of the identified model while the arm moves free (``ftc monitor --refine``).

Recursive least squares with exponential forgetting, in information form, on the same parameters as
the identification (:class:`~.model_error.ModelError`: the links' inertial parameters and, where it
was fitted, the sensor's error on the arm's loads), about the calibration file's values:

    L_k = lam L_{k-1} + (1 - lam) L_0 + A^T W A,   e_k = lam e_{k-1} + A^T W z,   theta = L^-1 e

with ``A`` the regressor of the frame's state less the tare's, ``z = external + A theta_applied`` (the
frame's residual as if the file's model were in use) and ``W`` the information of the residual as it
scatters (its running covariance: the sensor noise, and what no parameter explains: coloured noise,
friction's and gain's leftovers), over the frames it is correlated across (``corr_s`` of them at
``rate_hz``): white sensor noise alone would make a few thousand frames look certain to a fraction of
what the motion can tell, and every model difference look like drift. The
prior's information ``L_0`` (the identification's posterior) is forgotten toward itself, so a
direction the motion stops exciting returns to the file's value instead of winding up. Frames are
taken only while nothing touches the arm: no contact open, none closed within ``settle_s``, the
detection statistic under half its threshold, nothing saturated, at most ``rate_hz`` a second.
Every ``apply_s`` the estimate goes into the model (and the tare is taken again on its raw reading,
so the bias stays consistent with the model). ``drift`` compares it with the file: each link's mass
change with its standard error, and the chi-square of the whole change.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.inertials import N_PARAMS, body_params, set_body_params
from .model_error import ModelError
from .pipeline import Compensator


@dataclass(frozen=True)
class Drift:
    frames: int  # frames the refinement has taken
    applied: int  # times its estimate went into the model
    rms_file: float  # the free-motion residual under the calibration file's model (whitened by the noise)
    rms_refined: float  # under the refined model, over the same frames
    mass_change_kg: dict[str, float]  # per link, refined less the file's
    mass_std_kg: dict[str, float]

    MIN_FRAMES = 500  # 10 s of free motion at 50 frames a second
    GAIN = 0.95  # the refined model explains the motion 5 % better: the arm is not the file's

    @property
    def drifted(self) -> bool:
        return self.frames >= self.MIN_FRAMES and self.rms_refined < self.GAIN * self.rms_file

    def summary(self) -> str:
        verdict = ("DRIFTED from the calibration" if self.drifted else
                   "too little free motion yet" if self.frames < self.MIN_FRAMES else "as calibrated")
        head = (f"online refinement: {self.frames} free-motion frames, applied {self.applied} times; residual "
                f"(whitened RMS) {self.rms_file:.2f} under the calibration's model, {self.rms_refined:.2f} refined: "
                f"{verdict}")
        worst = max(self.mass_change_kg, key=lambda b: abs(self.mass_change_kg[b]) / self.mass_std_kg[b],
                    default=None)
        if worst is None:
            return head
        return head + (f"; largest link mass change {worst} {self.mass_change_kg[worst] * 1e3:+.0f} g "
                       f"(+-{self.mass_std_kg[worst] * 1e3:.0f} g)")


class OnlineRefiner:
    def __init__(self, compensator: Compensator, error: ModelError, noise_cov: np.ndarray,
                 time_constant_s: float = 120.0, rate_hz: float = 50.0, settle_s: float = 0.3,
                 apply_s: float = 1.0, corr_s: float = 1.0) -> None:
        self.compensator = compensator
        self.error = error
        m = compensator.model.model
        self.bodies = [m.body(b).name for b in error.body_ids]
        self.file_params = [body_params(m, b) for b in error.body_ids]
        self.file_gain = np.eye(6) if compensator.gain is None else compensator.gain.copy()
        prior = error.factor @ error.factor.T
        vals, vecs = np.linalg.eigh((prior + prior.T) / 2)
        vals = np.maximum(vals, max(vals.max(), 1e-30) * 1e-12)
        self.info0 = (vecs / vals) @ vecs.T
        self._prior_sqrt = vecs * np.sqrt(vals)  # prior = S S^T
        self.info = self.info0.copy()
        self.vec = np.zeros(len(prior))
        self.theta = np.zeros(len(prior))  # applied: the model holds file + theta
        self._scatter = np.asarray(noise_cov, dtype=float).copy()  # running covariance of the residual
        self._white = 1.0 / np.diag(noise_cov)
        self._ms = np.zeros(2)  # running mean squares (whitened) under the file's model and the refined one
        self._corr = max(1.0, corr_s * rate_hz)
        self.lam = float(np.exp(-1.0 / (time_constant_s * rate_hz)))
        self.every_ns = int(1e9 / rate_hz)
        self.settle_ns = int(settle_s * 1e9)
        self.apply_ns = int(apply_s * 1e9)
        self.frames = self.applied = 0
        self._last_ns: int | None = None
        self._applied_ns: int | None = None
        self._busy_until = -1
        self._tare: tuple[np.ndarray, np.ndarray] | None = None  # raw mean and q of the last tare

    def set_tare(self, raw_mean: np.ndarray, q: np.ndarray) -> None:
        self._tare = (np.asarray(raw_mean, dtype=float).copy(), np.asarray(q, dtype=float).copy())

    def touched(self, t_ns: int) -> None:
        """Something touches the arm (a contact is open): no frame until ``settle_s`` after."""
        self._busy_until = t_ns + self.settle_ns

    def observe(self, t_ns: int, external: np.ndarray, q, qd, qdd) -> bool:
        """One free frame (the caller's gate: no contact, nothing saturated, statistic low); True when
        the model was updated with it."""
        if t_ns < self._busy_until or (self._last_ns is not None and t_ns - self._last_ns < self.every_ns):
            return False
        self._last_ns = t_ns
        a = self.error.rows_regressor(q, qd, qdd)
        e = np.asarray(external, dtype=float)
        self._scatter = self.lam * self._scatter + (1 - self.lam) * np.outer(e, e)
        z = e + a @ self.theta
        self._ms = self.lam * self._ms + (1 - self.lam) * np.array([z @ (self._white * z), e @ (self._white * e)])
        aw = a.T @ np.linalg.inv(self._scatter * self._corr)
        self.info = self.lam * self.info + (1 - self.lam) * self.info0 + aw @ a
        self.vec = self.lam * self.vec + aw @ z
        self.frames += 1
        if self._applied_ns is None:
            self._applied_ns = t_ns
        if t_ns - self._applied_ns < self.apply_ns:
            return False
        self._applied_ns = t_ns
        self._apply(np.linalg.solve(self.info, self.vec))
        return True

    def _apply(self, theta: np.ndarray) -> None:
        comp = self.compensator
        m = comp.model.model
        for k, b in enumerate(self.error.body_ids):
            set_body_params(m, b, self.file_params[k] + theta[k * N_PARAMS:(k + 1) * N_PARAMS], nearest=True)
        comp.model.set_const()
        if self.error.gain:
            comp.gain = self.file_gain + theta[N_PARAMS * len(self.bodies):].reshape(6, 6)
        self.theta = theta
        self.applied += 1
        if self._tare is not None:
            zero = np.zeros_like(self._tare[1])
            comp.tare(self._tare[0], self._tare[1], zero, zero)

    def drift(self) -> Drift:
        """How far the refined model is from the file's: the residual under each, each link's mass change."""
        cov = np.linalg.inv(self.info)
        theta = np.linalg.solve(self.info, self.vec)
        mass = {b: float(theta[k * N_PARAMS]) for k, b in enumerate(self.bodies)}
        std = {b: float(np.sqrt(cov[k * N_PARAMS, k * N_PARAMS])) for k, b in enumerate(self.bodies)}
        norm = max(1.0 - self.lam ** max(self.frames, 1), 1e-12)  # the running means' start-up weight
        rms = np.sqrt(self._ms / norm / 6.0)
        return Drift(self.frames, self.applied, float(rms[0]), float(rms[1]), mass, std)
