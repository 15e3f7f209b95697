"""The external joint torques and their covariance, one joint sample at a time: the joint signals
(:mod:`.joint_signals`) through the momentum observer (:mod:`.momentum`).

Covariance of the residual r (n x n), per sample:

    cov = diag(white x f_white) + D M diag(sigma_v^2) M D + diag(s_slow^2) + diag(offset_var)

``f_white``, ``D = diag(sqrt(f_vel))``: the observer's variance factors for white torque and velocity noise
(``sigma_v`` rad/s the joint velocities' noise, 0 where the arm reports a clean velocity); ``s_slow``: the
slowly varying errors' 1-sigma (friction, static friction, model) through the observer's own lag, which
bounds the filtered error when the errors of consecutive samples are fully correlated (a static friction
that lasted until a joint broke loose still sits in r for about 1/K); ``offset_var``: the tracked torque
sensors' offsets' error variance (:mod:`.joint_offset`; zeros unless set); and, where identification gave its
parameters' covariance, that carried to the joint torques (:mod:`.joint_model_error`) -- at the currents
the model predicts without contact, ``i + r / kt`` (the null hypothesis the detector tests): at the measured
ones the torque constants' uncertainty (3.4 % for ur10e from its currents: their common scale with the
inertials) would count the contact's own torque as noise, a covariance growing with the contact along r
itself, which caps d2 near 1 / 0.034^2 whatever the force. The localization takes it at the measured
currents (:meth:`JointResidual.contact_cov`): there the contact's torque is indeed known only to that scale.

Whether a contact has ended (:meth:`JointResidual.release`): a joint that stands still holds any torque within
+-f_c by its static friction, which ``cov`` carries as a 1-sigma f_c, a Gaussian whose tails say that a
contact's torque twice f_c could be friction. Static friction is bounded: the offset is judged on the residual
beyond ``STUCK_MARGIN`` x that bound (its filtered value), against the covariance without it. Measured (ur16e,
typical world, a clamp on wrist_1): the clamped arm stalled, joint 2's sigma grew from 0.3 to 7 N m and d2 fell
below the release with 19 N m of contact torque on it against f_c = 10 N m: the clamp ended and began again.
"""
from __future__ import annotations

import numpy as np

from ..model import ArmModel
from ..scene import Scene
from .joint_model_error import JointModelError
from .joint_signals import JointSignals, Source
from .momentum import MomentumObserver, observer_step

# a longer interval between joint samples restarts the observer (about 7 of its lags at K = 150/s)
MAX_INTERVAL_NS = 50_000_000
# the static friction a stuck joint may hold, over the model's f_c (the friction model's own 1-sigma share)
STUCK_MARGIN = 1.25


class JointResidual:
    """r and its covariance from joint samples (see the module's notes). Not thread-safe."""

    def __init__(self, scene: Scene, arm: ArmModel, source: Source, *, gain: float = 150.0,
                 friction_rel_std: float = 0.25, model_rel_std: float = 0.02, velocity_noise_std: float = 0.0,
                 model_error: JointModelError | None = None, offset=None, identified_std=None) -> None:
        """``model_error``: the identified parameters' covariance in the joint torques, added to ``cov``;
        ``offset``, ``identified_std``: :class:`JointSignals`'."""
        self.signals = JointSignals(scene, source, friction_rel_std=friction_rel_std, model_rel_std=model_rel_std,
                                    offset=offset, identified_std=identified_std)
        self.observer = MomentumObserver(arm, gain=gain)
        n = arm.n_joints
        self.n = n
        self.velocity_var = float(velocity_noise_std) ** 2
        self.model_error = model_error
        self._slow = np.zeros(n)
        self._slow_now = np.zeros(n)
        self._stuck = np.zeros(n)  # the static friction's bound (N m), through the observer's lag as _slow
        self._sliding = np.zeros(n)  # _slow without the static friction
        self._model_cov = np.zeros((n, n))  # the model error's part of cov (at the contact-free currents)
        self.offset_var = np.zeros(n)  # N^2 m^2: the tracked offsets' error (set by the offset tracker)
        self.cov = np.zeros((n, n))

    def warm_up(self, home: np.ndarray) -> None:
        """Call the compiled kernels once on scratch state (the live observer keeps its own)."""
        n = self.n
        z, m = np.zeros(n), np.eye(n)
        observer_step(m, m, z, z, z, z, z, z, 1e-3, self.observer.gain, np.zeros(n), np.zeros(n), np.zeros(n),
                       np.zeros((2, n)))
        self.signals.slow_std(z, z, np.zeros(n))
        self.observer.dynamics(np.asarray(home, dtype=float), z)

    def reset(self) -> None:
        self.observer.reset()
        self._slow[:] = 0.0
        self._stuck[:] = 0.0
        self._sliding[:] = 0.0

    @property
    def r(self) -> np.ndarray:
        return self.observer.r

    def update(self, t_ns: int, q, qd, current=None, tau_j=None) -> tuple[np.ndarray, np.ndarray, bool]:
        """(r (n,) N m, cov (n, n), ready): ``ready`` False on the first sample after a (re)start, when
        the observer has no interval yet, and after a gap of more than ``MAX_INTERVAL_NS`` (a restart).
        Inputs must be finite."""
        qd = np.asarray(qd, dtype=float)
        obs = self.observer
        tau_in = self.signals.torque(qd, current, tau_j)
        if obs.started and t_ns - obs.last_t_ns > MAX_INTERVAL_NS:
            self.reset()  # the trapezoid over a long gap says little of what happened in it: start afresh
        first = not obs.started
        r = obs.update(t_ns, q, qd, tau_in)
        if first:
            self._slow[:] = self.signals.slow_std(qd, obs.bias, self._slow_now)
            self._stuck[:] = self.signals.stuck_std(qd)
            self._sliding[:] = _without(self._slow, self._stuck)
            return r, self.cov, False
        slow = self.signals.slow_std(qd, obs.model_torque(), self._slow_now)
        stuck = self.signals.stuck_std(qd)
        f_white, f_vel = obs.factors[0], obs.factors[1]
        a = 1.0 - 2.0 * f_white  # the filter's pole this interval, a = exp(-K dt)
        self._slow = a * self._slow + (1.0 - a) * slow
        self._stuck = a * self._stuck + (1.0 - a) * stuck
        self._sliding = a * self._sliding + (1.0 - a) * _without(slow, stuck)
        cov = self.cov
        cov[:] = 0.0
        if self.velocity_var > 0.0:
            d = np.sqrt(f_vel)
            m = obs.mass * d[:, None]
            cov += self.velocity_var * (m @ m.T)
        cov[np.diag_indices(self.n)] += self.signals.white_var * f_white + self._slow**2 + self.offset_var
        if self.model_error is not None:
            null = None if current is None else np.asarray(current, dtype=float) + r / self.signals.residuals.kt
            self._model_cov = self.model_error.cov(t_ns, q, qd, obs.qdd, null)
            cov += self._model_cov
        return r, cov, True

    def release(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The last sample's r and cov as the offset judges them (module notes): r (n,) less the stuck joints'
        static friction bound, towards 0 and no further; cov (n, n) without the static friction's share. None
        where no joint's signal carries static friction (joint torque sensors): r and cov themselves."""
        if not self.signals.sticks:
            return None
        r = self.observer.r
        r_free = np.sign(r) * np.maximum(np.abs(r) - STUCK_MARGIN * self._stuck, 0.0)
        cov = self.cov.copy()
        cov[np.diag_indices(self.n)] += self._sliding**2 - self._slow**2
        return r_free, cov

    def contact_cov(self, q, qd, current=None) -> np.ndarray:
        """The last sample's covariance with the model error at the measured currents ``current`` (n,) A
        in place of the contact-free ones (see the module's notes): for localizing a contact."""
        if self.model_error is None or current is None:
            return self.cov
        return self.cov - self._model_cov + self.model_error.cov_now(q, qd, self.observer.qdd, current)


def _without(std: np.ndarray, part: np.ndarray) -> np.ndarray:
    """A 1-sigma (n,) with one of its independent shares ``part`` taken out."""
    return np.sqrt(np.maximum(std**2 - part**2, 0.0))
