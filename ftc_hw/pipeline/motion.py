"""The compensation stage: a raw reading and the joint state in, the external wrench out, with what the
arm's motion model may get wrong right now (the acceleration estimate's lag, the identified model's
error) as covariance rows for the detector and the solver."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ftc_hw.compensation import Compensator, ModelError, OnlineRefiner, QddEstimator, RecentPeak
from ftc_hw.compensation.kernels import lag_rows, qdd_step
from ftc_hw.detection.kernels import window_change
from ftc_hw.model import ArmModel
from ftc_hw.scene import Scene

from .settings import PipelineSettings

G_REFRESH_NS = 10_000_000
QDD_RING = 64
LAG_WINDOW_SAMPLES = 3  # the detector's lag window spans at least this many sensor samples


class Compensated(NamedTuple):
    """One frame through the compensation stage. ``external`` (6,): the external contact wrench, sensor
    frame, scene convention; ``qdd`` (n,) rad/s^2 (given or estimated; None below the dynamics level);
    ``estimated``: qdd was estimated here; ``model_tau`` (n,) N m: the joint torques of the arm's own
    motion where the inverse dynamics gave them free (else None); ``model_error`` (k, 6): covariance rows
    of the compensation's error for the solver, ``judged`` (k', 6) for the detector (None: none)."""

    external: np.ndarray
    qdd: np.ndarray | None
    estimated: bool
    model_tau: np.ndarray | None
    model_error: np.ndarray | None
    judged: np.ndarray | None


class MotionStage:
    """Compensation with the lag model: bias, payload, gravity and dynamics taken away (``compensator``),
    the acceleration estimated from the joint velocities (``qdd``) and its lag error carried as
    covariance; the identified model's error (``identified_error``) and its online refinement
    (``refiner``)."""

    def __init__(self, scene: Scene, model: ArmModel, settings: PipelineSettings) -> None:
        c, m = settings.corrections, settings.motion
        self.compensator = Compensator(model, m.level, c.bias, gain=c.gain, frame=c.frame,
                                       contact_gain=c.contact_gain)
        self.level = self.compensator.level
        self.identified_error = (None if c.model_error is None else
                                 ModelError(model, list(c.model_error.bodies), c.model_error.body_cov,
                                            c.model_error.gain))
        self.refiner = (OnlineRefiner(self.compensator, self.identified_error, scene.sensor.noise_cov)
                        if m.refine and self.identified_error is not None else None)
        n = scene.n_joints
        self.qdd = QddEstimator(n, m.qdd_tau)
        # the recent acceleration estimates (a ring: enough rows for the lag window at 7 kHz)
        self._ring = np.zeros((QDD_RING, n))
        self._ring_t = np.full(QDD_RING, -1, dtype=np.int64)
        self._next = 0
        self._change = np.zeros(n)
        self._g_cache: np.ndarray | None = None
        self._g_rows = np.zeros((n, 6))  # _g_cache transposed, C-ordered
        self._g_time = 0
        self.lag_window_ns = int(2 * m.qdd_tau * 1e9)
        # The acceleration estimate lags by about a sample at a slow sensor's rate: the detector's window
        # holds a few samples, or a change one sample back is forgotten while the wrench still shows it
        # (a joint sticking at a reversal on dxl-arm, 100 Hz: 2 tau = 4 ms saw one step, a 7-sigma
        # alarm). The solver keeps 2 tau: a longer one cost dxl-arm's ideal p95 4.7 -> 6.5 mm.
        self._judge_window_ns = max(self.lag_window_ns, round(LAG_WINDOW_SAMPLES / scene.sensor.rate_hz * 1e9))
        self._judge_change = np.zeros(n)
        self.lag_floor = 0.02  # rad/s^2: below, the lag's wrench error is a fraction of the sensor noise
        self.lag_gain = 3.0  # the lag error exceeds the change over the window: 3 covers it with margin
        # Joint state interpolated over missed joint samples hides the motion in between: a transient
        # under way (a joint's friction flipping at a reversal rings for ~90 ms on ur5e) goes on
        # unseen, and its wrench reads as a contact. Over such a gap the lag error is taken as the
        # largest seen in the gap plus gap_hold_s before it (measured: 16 ms gaps placed anywhere in
        # a reversal gave d2 up to 1100, 20x the onset threshold; with the hold, none above 22).
        hold = settings.detection.gap_hold_s
        self.gap_hold_ns = None if hold is None else int(hold * 1e9)
        self._lag_peak = RecentPeak(n)
        self._gap_until = -1  # the hold lasts until then (the estimate's clock, ns)
        self._gap_span = 0

    def warm_up(self) -> None:
        """Call this stage's compiled kernels once (numba loads each from its cache on its first call)."""
        n = self._change.size
        window_change(self._ring, self._ring_t, 0, self.lag_window_ns, np.zeros(n), self._change)
        qdd_step(np.zeros(n), np.zeros(n), np.zeros(n), 0.5, 1e-3, np.zeros(n))
        lag_rows(self._g_rows, np.zeros(n), 1.0)

    def compensate(self, t_ns: int, raw, q: np.ndarray, qd, qdd, *, joint_torques: bool, in_contact: bool,
                   t_device_ns: int | None = None, joint_gap_ns: int = 0) -> Compensated:
        """One frame (see :meth:`ContactPipeline.process` for the arguments). ``joint_torques``: the solver
        will want the arm's joint torques (paid here only where the inverse dynamics runs anyway);
        ``in_contact``: the detector holds a contact (the gap hold widens onsets only)."""
        dynamics = self.level == "dynamics"
        if dynamics and qd is None:
            raise ValueError("dynamics compensation needs the joint velocities qd")
        lag_error = judge_lag = held = None
        t_clock = t_ns if t_device_ns is None else t_device_ns
        estimated = dynamics and qdd is None
        if estimated:
            qdd = self.qdd.update(t_clock * 1e-9, qd)
            lag_error, judge_lag = self._lag_errors(t_clock, qdd)
            held = self._gap_held(t_clock, lag_error, joint_gap_ns, in_contact)
        loads, model_tau = self.compensator.loads(q, qd, qdd, joint_torques=joint_torques and dynamics)
        external = self.compensator.contact_wrench(self.compensator.unbiased(raw), loads)
        model_error = None if lag_error is None else self._model_error(t_clock, lag_error)
        judge_lag = judge_lag if held is None else held
        judged = (model_error if judge_lag is lag_error
                  else None if judge_lag is None else self._model_error(t_clock, judge_lag))
        if self.identified_error is not None:  # what the identified model may still get wrong
            z = np.zeros_like(q)
            rows = self.identified_error.rows(t_ns, q, z if qd is None else qd, z if qdd is None else qdd)
            model_error = rows if model_error is None else np.vstack([model_error, rows])
            judged = rows if judged is None else np.vstack([judged, rows])
        return Compensated(external, qdd, estimated, model_tau, model_error, judged)

    def joint_torques(self, q: np.ndarray, qd, qdd, model_tau: np.ndarray | None) -> np.ndarray:
        """The joint torques (n,) N m the arm's own motion needs: ``model_tau`` where the frame had them,
        else an extra pass of the inverse dynamics at the gravity level (none at the bias level)."""
        if model_tau is not None:
            return model_tau
        if self.level == "gravity":
            return self.compensator.loads(q, qd, qdd, joint_torques=True)[1]
        return np.zeros(q.size)

    def refine(self, t_ns: int, external: np.ndarray, q: np.ndarray, qd, qdd, *, touched: bool,
               clearly_free: bool) -> None:
        """Feed the online refiner (if any) a frame: ``touched`` (in or near a contact, saturated) holds it
        off; ``clearly_free`` frames refine the model."""
        if self.refiner is None or qd is None or qdd is None:
            return
        if touched:
            self.refiner.touched(t_ns)
        elif clearly_free:
            self.refiner.observe(t_ns, external, q, qd, qdd)

    def tare(self, raw_mean, q) -> None:
        """Re-zero on the mean reading ``raw_mean`` of still, untouched frames at joint angles ``q``."""
        zero = np.zeros(self._change.size)
        self.compensator.tare(raw_mean, q, zero, zero)
        if self.identified_error is not None:
            self.identified_error.set_tare(q)
        if self.refiner is not None:
            self.refiner.set_tare(raw_mean, q)

    def restart(self) -> None:
        """The joint stream was lost and is back: the acceleration estimate starts afresh."""
        self.qdd.reset()
        self._ring_t[:] = -1
        self._gap_until = -1

    def _model_error(self, t_clock: int, lag_error: np.ndarray) -> np.ndarray:
        """The estimated acceleration lags the true one by about the recent change: its effect on the
        compensated wrench is the model's response to that change (linear in qdd; per joint its own
        term, so only the size of the change matters, not its sign). Rows: one per joint. (An
        uncertainty, not a correction: the Jacobian is refreshed every G_REFRESH_NS, ~1 % of change
        at 1 rad/s.)"""
        if self._g_cache is None or t_clock - self._g_time >= G_REFRESH_NS:
            self._g_cache = self.compensator.model.wrench_qdd_jacobian()
            # rows contiguous: the kernels compiled (and warmed) for C-ordered rows take them as they are
            self._g_rows = np.ascontiguousarray(self._g_cache.T)
            self._g_time = t_clock
        return lag_rows(self._g_rows, lag_error, self.lag_floor)

    def _gap_held(self, t_clock: int, lag_error: np.ndarray | None, joint_gap_ns: int,
                  in_contact: bool) -> np.ndarray | None:
        """The lag error the detector judges an onset with over missed joint samples (None: the
        frame's own). Over a gap and until the acceleration estimate has caught up after it (5 tau:
        within 1 %), the largest lag error of the gap plus gap_hold before it. Only for the onset: in
        contact the history holds the contact's own transients, and widening the fit by them made
        the localization worse (replays of 3 ur5e runs: per-contact RMS 1.6-2.4 mm -> 1.6-5.2 mm)."""
        if lag_error is not None:
            self._lag_peak.add(t_clock, lag_error)
        if self.gap_hold_ns is None:
            return None
        if joint_gap_ns > 0:
            self._gap_until = t_clock + 5 * self.lag_window_ns // 2
            self._gap_span = joint_gap_ns
        if t_clock > self._gap_until or in_contact:
            return None
        # this frame's own lag error is in the newest bucket: the maximum covers it
        return self._lag_peak.max_since(t_clock - self.gap_hold_ns - self._gap_span, t_clock)

    def _lag_errors(self, t_ns: int, qdd: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
        """The largest change of the acceleration estimate over the last lag window (2 tau), per
        joint: the size of the estimator's lag error right now; None when it is negligible (saves an
        inverse dynamics). The largest change, not the change across the window: after a short pulse
        the estimate comes back down and its two ends can agree while it still lags by the pulse.
        Returns the solver's (over 2 tau) and the detector's (over at least three sensor samples:
        the same object when the sensor is fast enough for 2 tau to hold them)."""
        i = self._next
        solver = self._lag_over(t_ns, qdd, self.lag_window_ns, self._change)
        judge = (solver if self._judge_window_ns == self.lag_window_ns
                 else self._lag_over(t_ns, qdd, self._judge_window_ns, self._judge_change))
        self._ring[i] = qdd
        self._ring_t[i] = t_ns
        self._next = (i + 1) % QDD_RING
        return solver, judge

    def _lag_over(self, t_ns: int, qdd: np.ndarray, window_ns: int, change: np.ndarray) -> np.ndarray | None:
        biggest = window_change(self._ring, self._ring_t, t_ns, window_ns, qdd, change)
        return None if self.lag_gain * biggest < self.lag_floor else self.lag_gain * change
