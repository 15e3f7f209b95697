"""The localization stage: where on the arm's surface a contact is and how hard, from the external wrench
(and the joint torques from the motor currents), with the arm's reaction to an impact refitted."""
from __future__ import annotations

import math
from collections import deque
from dataclasses import replace

import numpy as np

from ftc_hw.compensation import JointResiduals
from ftc_hw.detection import Detection
from ftc_hw.model import ArmModel
from ftc_hw.scene import Scene
from ftc_hw.solver import ContactEstimate, Solver, make_solver

from .settings import PipelineSettings

# an arm's reaction to a contact that counts against the sensor noise (chi-square, 1 dof, p = 0.999)
IMPACT_CHI2 = 10.83
IMPACT_PASSES = 2


class LocalizationStage:
    """The solver (``solver``), the joint torques' residuals from the currents (``residuals``; None:
    currents not used) and the impact refit: within ``impact_window_s`` of an onset the arm's reaction
    to the contact is an unknown of the fit."""

    def __init__(self, scene: Scene, model_scene: Scene, model: ArmModel, settings: PipelineSettings) -> None:
        self.model = model
        self.solver: Solver = make_solver(model, settings.localization.method)
        self.residuals = JointResiduals(model_scene) if settings.motion.use_currents else None
        extra = settings.detection.extra_cov
        self.extra_cov = None if extra is None else np.asarray(extra, dtype=float).reshape(6, 6)
        window = settings.motion.impact_window_s
        # how long after a contact's start the estimated acceleration may still miss the arm's
        # reaction to it (None: never re-weigh; see _impact_solve)
        self.impact_window_ns = None if window is None else int(window * 1e9)
        self._noise_inv = np.linalg.inv(scene.sensor.noise_cov)
        self._kt = np.asarray(model_scene.robot.torque_constant, dtype=float)
        self._pre_current: deque[np.ndarray] = deque(maxlen=3)  # the last frames before a contact
        self._impact_dtau: np.ndarray | None = None
        self._impact_seed: ContactEstimate | None = None  # the last impact estimate of this contact
        self.solved_poses = self.solver.solved_body_poses  # the kinematics of the frame just solved, if any

    def warm_up(self, home: np.ndarray) -> None:
        """Call this stage's compiled kernels once (numba loads each from its cache on its first call)."""
        n = home.size
        if self.residuals is not None:
            self.residuals.external_torques(np.zeros(n), np.zeros(n), np.zeros(n))
        self.solver.solve(np.array([0.0, 0.0, 10.0, 0.0, 0.0, 0.0]), home,
                          tau_ext=np.zeros(n), tau_std=np.ones(n), extra_cov=np.zeros((6, 6)))

    def observe_currents(self, current, in_contact: bool) -> None:
        """The motor currents (n,) A of a frame whose acceleration was estimated: kept from the frames
        before a contact; in contact, the joint controllers' reaction since then, in torque."""
        self._impact_dtau = None
        if not in_contact:
            self._pre_current.append(np.asarray(current, dtype=float))
        elif self._pre_current:
            self._impact_dtau = self._kt * (np.asarray(current, dtype=float) - self._pre_current[0])

    def clear_frame(self) -> None:
        """A frame without currents (or with a given acceleration): no reaction of the joint controllers."""
        self._impact_dtau = None

    def external_torques(self, model_tau: np.ndarray, current, qd) -> tuple[np.ndarray, np.ndarray]:
        """The external joint torques (n,) N m and their 1-sigma from the currents."""
        return self.residuals.external_torques(model_tau, current, qd)

    def in_impact(self, det: Detection, t_ns: int) -> bool:
        return (self.impact_window_ns is not None and det.onset_t_ns is not None
                and t_ns - det.onset_t_ns <= self.impact_window_ns)

    def begin_contact(self) -> None:
        self._impact_seed = None

    def restart(self) -> None:
        """The joint stream was lost and is back: the currents before a contact start afresh."""
        self._pre_current.clear()

    def solve(self, external, q, tau_ext, tau_std, saturated: bool, model_error, impact: bool) -> ContactEstimate:
        """One frame's estimate; ``model_error`` (k, 6) covariance rows of the compensation's error;
        ``impact``: the frame is within the impact window of its contact's onset."""
        e = None
        if impact and self._impact_seed is not None:
            # within an impact the last frame's estimate gives the reaction's direction: one solve
            e = self._impact_solve(self._impact_seed, external, q, tau_ext, tau_std, saturated, 1)
        if e is None:
            e = self.solver.solve(external, q, tau_ext=tau_ext, saturated=saturated, tau_std=tau_std,
                                  extra_cov=self._extra(model_error))
            if impact:
                e = self._impact_solve(e, external, q, tau_ext, tau_std, saturated, IMPACT_PASSES) or e
        self._impact_seed = e if impact and "impact" in e.flags else None
        return e

    def _extra(self, model_error: np.ndarray | None) -> np.ndarray | None:
        """The compensation's own uncertainty for a frame: the acceleration estimate's lag error weighs
        on the fit as it does on detection."""
        extra = self.extra_cov
        if model_error is not None:
            extra = model_error.T @ model_error if extra is None else extra + model_error.T @ model_error
        return extra

    def _impact_solve(self, e: ContactEstimate, external, q, tau_ext, tau_std, saturated: bool,
                      passes: int) -> ContactEstimate | None:
        """Solve again with the arm's reaction to the contact as an unknown, and flag ``impact``
        where that reaction is larger than the sensor noise; ``e``: the estimate that gives the
        reaction's direction. None where there is no such reaction (or no estimate to give it).

        A contact accelerates the arm at once (M^-1 J^T f); the acceleration estimate, a causal filter
        of the joint velocities, sees that only a few samples later. Until then the compensated
        wrench holds an unknown fraction (0 to 1) of the wrench that acceleration produces at the
        sensor, G M^-1 J^T f, and likewise of the joint controllers' answer since the contact began
        (from the motor currents). One unit of variance along each of those directions lets the fit
        leave them out. It replaces the lag model (which would count the reaction twice). The
        estimate is still provisional, and the contact's track fuses none of these."""
        out = None
        model = self.model
        g = d2 = None  # both depend on q only: computed once per frame
        for _ in range(passes):  # the direction comes from an estimate: a second pass refines it
            if not (e.contact and e.link) or not math.isfinite(float(e.point.sum() + e.force.sum())):
                break
            acc = model.contact_acceleration(q, e.link, e.point, e.force)
            if g is None:
                g = model.wrench_qdd_jacobian()  # the kinematics are at q after contact_acceleration
            d = g @ acc
            if float(d @ self._noise_inv @ d) <= IMPACT_CHI2:
                break
            cov = np.outer(d, d) if self.extra_cov is None else self.extra_cov + np.outer(d, d)
            if self._impact_dtau is not None:
                if d2 is None:
                    d2 = g @ model.torque_acceleration(q, self._impact_dtau)
                cov += np.outer(d2, d2)
            e = out = self.solver.solve(external, q, tau_ext=tau_ext, saturated=saturated, tau_std=tau_std,
                                        extra_cov=cov)
        return None if out is None else replace(out, flags=(*out.flags, "impact"))
