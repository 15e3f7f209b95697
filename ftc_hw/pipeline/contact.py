"""The per-frame contact pipeline: raw wrench and joint state in; external wrench, detection,
estimate and contact events out. The live monitor, replay and the benchmarks all run this.

Four stages, each owning its state and its warm-up (their roles: :mod:`.stages`):

    raw, q, qd, current
      -> MotionStage         compensation with the lag model        -> external wrench, error rows
      -> ContactDetector     chi-square of the external wrench      -> onset / in contact / offset
      -> LocalizationStage   where and how hard, the impact refit   -> ContactEstimate (in contact)
      -> ContactEvents       the contact's track and its events     -> ContactEvent (onset/update/offset)
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ftc_hw.bus import ContactEvent
from ftc_hw.detection import ContactDetector, Detection
from ftc_hw.detection.kernels import mahalanobis2, quad_sum
from ftc_hw.model import ArmModel
from ftc_hw.scene import Scene
from ftc_hw.solver import ContactEstimate

from .events import ContactEvents, PreviousFrame
from .localization import LocalizationStage
from .motion import MotionStage
from .settings import PipelineSettings
from .stages import Compensation, Detector, Events, Localization, PipelineView
from .timing import NO_CLOCK, StageClock


@dataclass(frozen=True, slots=True)
class FrameResult:
    t_ns: int
    external: np.ndarray  # external contact wrench, sensor frame, scene convention
    detection: Detection
    estimate: ContactEstimate | None  # while in contact
    tau_ext: np.ndarray | None  # J^T p from the currents, N m
    events: tuple[ContactEvent, ...]


# the identified joint terms the scene's [robot] holds (the others, rotor inertia and torque sensor offsets,
# the joint pipeline takes from the corrections itself)
ROBOT_JOINT_TERMS = ("torque_constant", "friction_viscous", "friction_coulomb")


def corrected_scene(scene: Scene, settings: PipelineSettings) -> Scene:
    """The scene the pipeline's model is built from: a calibrated gravity and identified joints."""
    c = settings.corrections
    out = scene if c.gravity is None else replace(scene, gravity=np.asarray(c.gravity, dtype=float))
    terms = {k: np.asarray(v, dtype=float) for k, v in (c.joints or {}).items() if k in ROBOT_JOINT_TERMS}
    if terms:
        out = replace(out, robot=replace(out.robot, **terms))
    return out


POWER_PERIOD_NS = 5_000_000  # the contact point's velocity is recomputed every 5 ms (a Jacobian: ~20 us)


class ContactPower:
    """The power ``F . v`` (W) a contact puts into the arm: its estimate's force (base frame) on the velocity
    of its point (``J(q) qd``, recomputed every ``POWER_PERIOD_NS``, the last one between); None without a
    sound estimate or joint velocities (the contact's class then goes on without its motion)."""

    def __init__(self, model: ArmModel) -> None:
        self.model = model
        self._t_ns = -(2**62)
        self._v = np.zeros(3)

    def __call__(self, t_ns: int, e: ContactEstimate | None, q: np.ndarray, qd) -> float | None:
        if e is None or not e.contact or not e.link or qd is None or not np.isfinite(e.force).all():
            return None
        if t_ns - self._t_ns >= POWER_PERIOD_NS or t_ns < self._t_ns:
            self._v = self.model.jacobian(q, e.link, e.point) @ np.asarray(qd, dtype=float)
            self._t_ns = t_ns
        return float(e.force @ self._v)


class ContactPipeline(PipelineView):
    """One scene's compensation, detection, localization and events. Not thread-safe: one per reader
    thread. ``clock``: told each stage's end in every frame (``ftc bench pipeline`` times the stages
    with it; the default does nothing)."""

    def __init__(self, scene: Scene, settings: PipelineSettings | None = None, *,
                 clock: StageClock = NO_CLOCK) -> None:
        self.scene = scene
        self.settings = settings = settings or PipelineSettings()
        model_scene = corrected_scene(scene, settings)
        model = ArmModel(model_scene, settings.corrections.payload, settings.corrections.inertials)
        self.motion: Compensation = MotionStage(scene, model, settings)
        d = settings.detection
        cov = scene.sensor.noise_cov + (np.zeros((6, 6)) if d.extra_cov is None else np.reshape(d.extra_cov, (6, 6)))
        self.detector: Detector = ContactDetector(cov, p_false=d.p_false, n_on=d.n_on, n_off=d.n_off)
        localization = LocalizationStage(scene, model_scene, model, settings)
        self.localization: Localization = localization
        self.events: Events = ContactEvents(scene, model, localization.solver.body_poses, settings)
        self._power = ContactPower(model)
        self.clock = clock
        self.warm_up()

    @property
    def level(self):
        return self.motion.level

    def warm_up(self) -> None:
        """Call every compiled kernel once now. numba loads each from its cache on its first call,
        tens of milliseconds that the first contact would otherwise wait for, and its reflex stop
        with it (measured: 28-32 ms from the onset sample to the stop, 3-6 ms once loaded)."""
        row = np.zeros((1, 6))
        mahalanobis2(np.zeros(6), self.detector.cov, row)
        quad_sum(row, self.detector.inv)
        self.motion.warm_up()
        self.localization.warm_up(np.asarray(self.scene.robot.home, dtype=float))
        self.events.warm_up()

    def tare(self, raw_mean, q, samples: int, t_ns: int, tau_j=None) -> None:
        """Re-zero on the mean ``raw_mean`` of ``samples`` still, untouched frames at joint angles q
        (taken by host time ``t_ns``): the bias is then known to 1/samples of the sensor's noise."""
        self.motion.tare(raw_mean, q)
        self.events.set_bias(1.0 / max(int(samples), 1), t_ns)

    def process(self, t_ns: int, raw, q, qd=None, current=None, qdd=None, saturated: bool = False,
                t_device_ns: int | None = None, joint_gap_ns: int = 0) -> FrameResult:
        """One F/T sample at host time t_ns: ``raw`` (6,) the reading, ``q``, ``qd``, ``current``, ``qdd``
        (n,) the joint state at that time (rad, rad/s, A, rad/s^2; qdd None: estimated from qd).
        ``t_device_ns``: the sample's device time, the steadier clock for differentiating qd (else t_ns).
        ``joint_gap_ns``: > 0 when that joint state was interpolated (or extrapolated) over missed
        joint samples: the span, ns, between the samples it was made from."""
        clock = self.clock
        clock.begin()
        q = np.asarray(q, dtype=float)
        want_tau = self.localization.residuals is not None and current is not None
        m = self.motion.compensate(t_ns, raw, q, qd, qdd, joint_torques=want_tau, in_contact=self.detector.active,
                                   t_device_ns=t_device_ns, joint_gap_ns=joint_gap_ns)
        clock.lap("compensation")
        det = self.detector.update(t_ns, m.external, m.judged)
        clock.lap("detection")
        estimate = tau_ext = None
        if det.active:
            tau_ext, estimate = self._localize(t_ns, det, m, q, qd, current, saturated, want_tau)
            clock.lap("localization")
        elif current is not None and m.estimated:
            self.localization.observe_currents(current, False)
        else:
            self.localization.clear_frame()
        ended = det.change == "offset"
        power = self._power(t_ns, estimate, q, qd) if det.active else None
        events = self.events.frame_events(t_ns, det, estimate, m.external, q, power) if det.active or ended else []
        if self.events.track is not None:
            self.events.previous = PreviousFrame(t_ns, m.external, q.copy(), m.model_error, saturated)
        clock.lap("events")
        self.motion.refine(t_ns, m.external, q, qd, m.qdd, touched=det.active or ended or saturated,
                           clearly_free=det.d2 < 0.5 * self.detector.on)  # a rising contact stays out
        clock.end()
        return FrameResult(t_ns, m.external, det, estimate, tau_ext, tuple(events))

    def _localize(self, t_ns: int, det: Detection, m, q: np.ndarray, qd, current, saturated: bool,
                  want_tau: bool) -> tuple[np.ndarray | None, ContactEstimate]:
        """A frame in contact: its external joint torques (where the currents give them) and its estimate,
        fused into the contact's track."""
        loc = self.localization
        if current is not None and m.estimated:
            loc.observe_currents(current, True)
        else:
            loc.clear_frame()
        tau_ext = tau_std = None
        if want_tau:
            model_tau = self.motion.joint_torques(q, qd, m.qdd, m.model_tau)
            tau_ext, tau_std = loc.external_torques(model_tau, current, qd if qd is not None else np.zeros_like(q))
        impact = m.estimated and loc.in_impact(det, t_ns)
        if det.change == "onset":
            loc.begin_contact()
            if self.events.track is not None:
                self.events.track.reset()
                if not impact:
                    self._fuse_previous(det, tau_ext, tau_std)
        estimate = loc.solve(m.external, q, tau_ext, tau_std, saturated, m.model_error, impact)
        self.events.fuse(t_ns, estimate, q, loc.solved_poses())
        return tau_ext, estimate

    def _fuse_previous(self, det: Detection, tau_ext, tau_std) -> None:
        """The onset goes out at the detector's n_on-th sample above the threshold; the sample before
        it, already above, is fused first (with this frame's joint torques: they change slowly), so
        the onset's point rests on two frames instead of one. Costs one solve, at onsets only; none
        in an impact, whose estimates the track does not fuse."""
        prev = self.events.previous
        if prev is None or det.onset_t_ns is None or prev.t_ns < det.onset_t_ns:
            return
        e = self.localization.solve(prev.external, prev.q, tau_ext, tau_std, prev.saturated, prev.model_error, False)
        self.events.track.update(prev.t_ns, e, prev.q, self.localization.solved_poses())

    def close_contact(self, t_ns: int, probability: float | None = None, *, lost: bool = False) -> ContactEvent:
        """The open contact's offset (:meth:`ContactEvents.close_contact`). ``lost``: closed because a
        stream was lost (flagged ``lost``; the detector and the track start afresh)."""
        if lost:
            self.detector.reset()
        return self.events.close_contact(t_ns, probability, lost=lost)

    def restart_motion(self) -> None:
        """The joint stream was lost and is back: what was estimated from its past (the acceleration,
        the currents before a contact, the last frame) starts afresh."""
        self.motion.restart()
        self.localization.restart()
        self.events.previous = None
