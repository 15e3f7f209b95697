"""The contact pipeline driven by JOINT samples, for scenes whose sensing has no base F/T sensor: motor
currents or joint torque sensors (and a flange F/T sensor's wrench where the scene uses one).

    q, qd, current | tau_J  (a flange wrench)
      -> JointResidual        momentum observer            -> r (n,) N m, its covariance (n, n)
      -> JointDetector        chi-square of r              -> onset / in contact / offset
      -> JointContactSolver   candidates on the surfaces   -> ContactEstimate (in contact): link, point,
                                                              force, covariance, candidates, ``ambiguous``
      -> ContactEvents        the contact's track, events  -> ContactEvent (onset / update / offset)

The events stage is ContactPipeline's, unchanged; it is given the estimate's contact wrench as the F/T
path's "external wrench" (sensor frame, scene convention), which it uses for the contact's force figures
and the line of action into the meshes, and the chosen link's posterior probability as the frame's.
"""
from __future__ import annotations

import math

import numpy as np

from ftc_hw.bus import ContactEvent
from ftc_hw.compensation import Compensator
from ftc_hw.compensation.joint_model_error import JointModelError
from ftc_hw.compensation.joint_offset import OffsetTracker
from ftc_hw.compensation.joint_residual import JointResidual
from ftc_hw.detection import Detection
from ftc_hw.detection.joint import JointDetector
from ftc_hw.model import ArmModel
from ftc_hw.scene import Scene
from ftc_hw.solver import ContactEstimate
from ftc_hw.solver.joint import JointContactSolver, invalid_estimate

from .contact import ContactPipeline, FrameResult, corrected_scene
from .events import ContactEvents
from .settings import PipelineSettings
from .stages import PipelineView
from .timing import NO_CLOCK, StageClock

CORRELATED_FRAMES = 1.0  # the track's chain_ratio: the share of one frame's error no number of frames averages


class JointContactPipeline(PipelineView):
    """One scene's joint-signal residual, detection, localization and events (see the module's notes).
    Not thread-safe: one per reader thread. ``invalid_frames`` counts the samples refused (non-finite or
    missing input): each is a frame flagged ``invalid_input``, the observer bridging over it."""

    def __init__(self, scene: Scene, settings: PipelineSettings | None = None, *,
                 clock: StageClock = NO_CLOCK) -> None:
        self.scene = scene
        self.settings = settings = settings or PipelineSettings()
        sensing = scene.sensing
        if not sensing.joint:
            raise ValueError(f"scene {scene.name!r} uses no joint signals (sensing: {sensing.label()})")
        self.source = "joint_torques" if sensing.joint_torques else "currents"
        js, c = settings.joint, settings.corrections
        model_scene = corrected_scene(scene, settings)
        self.model = model = ArmModel(model_scene, c.payload, c.inertials)
        joints = c.joints or {}
        if "rotor_inertia" in joints:  # identified beyond the model's armature (the currents' side only)
            add_rotor_inertia(model, np.asarray(joints["rotor_inertia"], dtype=float))
        me = c.model_error
        identified = (c.joint_residual_std or {}).get(self.source)
        self.residual = JointResidual(model_scene, model, self.source, gain=js.observer_gain,
                                      friction_rel_std=js.friction_rel_std, model_rel_std=js.model_rel_std,
                                      velocity_noise_std=js.velocity_noise_std,
                                      model_error=None if me is None else JointModelError(
                                          model, me.bodies, me.cov, me.gain, joints=me.joints,
                                          source=self.source),
                                      offset=joints.get("torque_offset") if self.source == "joint_torques" else None,
                                      identified_std=identified)
        # the torque sensors' offsets tracked while the arm is clearly free (the currents have none)
        self.offsets = OffsetTracker(js.offset, scene.joint_torque.range) if self.source == "joint_torques" else None
        self._offset0 = self.residual.signals.offset.copy()  # identified or tared: the tracker's reference
        self.flange = FlangeWrench(scene, model, settings) if sensing.ft == "flange" else None
        d = settings.detection
        dims = scene.n_joints + (6 if self.flange is not None else 0)  # the flange wrench joins the test
        subspaces = link_subspaces(model, scene, dims) if js.link_subspaces else None
        self.detector = JointDetector(dims, p_false=d.p_false, n_on=d.n_on, n_off=d.n_off, subspaces=subspaces)
        self.tested = np.zeros(dims)  # the vector the detector tested last: r, or [r, w] with a flange sensor
        self.solver = JointContactSolver(model, spacing=js.spacing_m, fine_spacing=js.fine_spacing_m,
                                         friction_mu=js.friction_mu, force_prior=js.force_prior_n,
                                         ambiguity_radius=js.ambiguity_radius_m, ambiguity_mass=js.ambiguity_mass,
                                         significant_sigma=js.significant_sigma)
        self.events = ContactEvents(scene, model, self.solver.body_poses, settings)
        if self.events.track is not None:
            # consecutive estimates share the observer's lag and the slow errors (friction, the model): the
            # track may average their noise but never claim better than one frame's error (measured, dxl-arm
            # ideal, 16 distal probes: 95 % coverage 0.76 with the F/T path's 0.1, 0.99 with 1)
            self.events.track.chain_ratio = CORRELATED_FRAMES
        self.clock = clock
        self.localize_period_ns = int(js.localize_period_s * 1e9)
        self.invalid_frames = 0
        self._solved_ns = 0
        self._last: ContactEstimate | None = None
        self._zero6 = np.zeros(6)
        self.warm_up()

    @property
    def level(self) -> str:
        return "dynamics"

    def warm_up(self) -> None:
        """Call every compiled kernel once now (numba loads each from its cache on its first call)."""
        home = np.asarray(self.scene.robot.home, dtype=float)
        n = home.size
        self.residual.warm_up(home)
        self.detector.statistic(np.zeros(n), np.eye(n))
        if self.flange is not None:
            self.flange.contact(np.zeros(6), home, np.zeros(n), np.zeros(n))
        self.solver.solve(np.ones(n), np.eye(n), home)
        self.events.warm_up()

    def process_joints(self, t_ns: int, q, qd, *, current=None, tau_j=None, wrench=None,
                       t_device_ns: int | None = None, joint_gap_ns: int = 0) -> FrameResult:
        """One joint sample at host time t_ns: ``q``, ``qd`` (n,) rad, rad/s; ``current`` (n,) A (scenes
        using currents) or ``tau_j`` (n,) N m (joint torque sensors); ``wrench`` (6,) the flange F/T
        reading at that time (sensor frame, scene convention) when the scene uses one. ``t_device_ns``:
        the sample's device time, the steadier clock for the observer's intervals (else t_ns).
        ``joint_gap_ns`` > 0: samples were missed before this one (the observer integrates over the gap)."""
        clock = self.clock
        clock.begin()
        q = np.asarray(q, dtype=float)
        qd = np.asarray(qd, dtype=float)
        signal = tau_j if self.source == "joint_torques" else current
        if not _finite(q, qd, signal, self.scene.n_joints):
            return self._invalid(t_ns)
        t_obs = t_ns if t_device_ns is None else int(t_device_ns)
        r, cov, ready = self.residual.update(t_obs, q, qd, current=current, tau_j=tau_j)
        clock.lap("compensation")
        if not ready:
            clock.end()
            return FrameResult(t_ns, self._zero6, _idle(self.detector), None, r.copy(), ())
        w = None
        if self.flange is not None:
            w = self.flange.contact(wrench, q, qd, self.residual.observer.qdd)
            z, z_cov = self.flange.stacked(r, cov, w)
        else:
            z, z_cov = r, cov
        self.tested = z
        release = self._release(w) if self.detector.active else None
        det = self.detector.update(t_ns, z, z_cov, release)
        self._track_offsets(t_ns, det)
        clock.lap("detection")
        estimate = None
        external = self._zero6
        if det.active:
            estimate = self._localize(t_ns, det, r, q, qd, current, w)
            external = self._external(estimate, q)
            clock.lap("localization")
        events: list[ContactEvent] = []
        if det.active or det.change == "offset":
            det_out = det if estimate is None else Detection(det.active, det.d2, det.blind, _link_probability(estimate),
                                                             det.change, det.onset_t_ns)
            # the power the contact puts into the arm: the external joint torques on the joint velocities
            events = self.events.frame_events(t_ns, det_out, estimate, external, q, float(r @ qd))
        if det.change == "offset":
            self._last = None
        clock.lap("events")
        clock.end()
        return FrameResult(t_ns, external, det, estimate, r.copy(), tuple(events))

    def _release(self, w) -> tuple[np.ndarray, np.ndarray] | None:
        """What the offset is judged on (``JointResidual.release``), stacked with the flange's wrench as z is;
        None: z itself."""
        release = self.residual.release()
        if release is None or self.flange is None:
            return release
        return self.flange.stacked(*release, w)

    def _track_offsets(self, t_ns: int, det: Detection) -> None:
        """The torque sensors' offsets refined on this sample where it is clearly contact-free (from the next
        sample on), their uncertainty into the residual's covariance."""
        tracker = self.offsets
        if tracker is None:
            return
        if tracker.observe(t_ns, self.residual.r, free=not det.active, statistic_ratio=det.d2 / self.detector.on):
            self.residual.signals.offset = self._offset0 + tracker.correction
        self.residual.offset_var = tracker.var

    def _localize(self, t_ns: int, det: Detection, r, q, qd, current, w) -> ContactEstimate:
        """A frame in contact: the estimate (at the onset, then at most every ``localize_period_s``; else
        the last one), fused into the contact's track; r's covariance with the contact's own torque
        through the torque constants' uncertainty (``JointResidual.contact_cov``)."""
        if det.change == "onset":
            self._last = None
            if self.events.track is not None:
                self.events.track.reset()
        if self._last is not None and t_ns - self._solved_ns < self.localize_period_ns:
            return self._last
        self._solved_ns = t_ns
        w_cov = None if w is None else self.flange.cov
        cov = self.residual.contact_cov(q, qd, current if self.source == "currents" else None)
        e = self.solver.solve(r, cov, q, wrench=w, wrench_cov=w_cov)
        self._last = e
        self.events.fuse(t_ns, e, q, self.solver.solved_body_poses())
        return e

    def _external(self, e: ContactEstimate, q: np.ndarray) -> np.ndarray:
        """The estimate's contact wrench as the F/T path's external wrench: the change it makes in the
        scene's sensor reading (sensor frame, about its origin), or in base axes about the base origin
        where the scene has no F/T sensor."""
        if not (e.contact and math.isfinite(float(e.force.sum() + e.point.sum()))):
            return self._zero6
        b_T_s = self.model.base_T_sensor(q)  # the identity where the scene has no sensor
        rot, origin = b_T_s[:3, :3], b_T_s[:3, 3]
        f, c = e.force, e.point - origin
        moment = np.array([c[1] * f[2] - c[2] * f[1], c[2] * f[0] - c[0] * f[2], c[0] * f[1] - c[1] * f[0]])
        w = np.concatenate([rot.T @ f, rot.T @ moment])
        return w if self.scene.sensor is None else -self.scene.sensor.reading_sign * w

    def _invalid(self, t_ns: int) -> FrameResult:
        self.invalid_frames += 1
        self.clock.end()
        return FrameResult(t_ns, self._zero6, _idle(self.detector, math.nan), invalid_estimate(), None, ())

    def tare(self, raw_mean, q, samples: int, t_ns: int, tau_j=None) -> None:
        """Re-zero at rest on the means of ``samples`` still, untouched samples at q: the flange sensor on
        ``raw_mean`` (its readings), the joint torque sensors' offsets on ``tau_j`` (theirs, against the
        model's gravity torques at q). Motor currents take no tare (static friction holds anything within
        +-f_c at rest)."""
        if self.flange is not None and raw_mean is not None and np.size(raw_mean) == 6:
            self.flange.compensator.tare(raw_mean, q)
            self.events.set_bias(1.0 / max(int(samples), 1), t_ns)
        if self.source == "joint_torques" and tau_j is not None:
            q = np.asarray(q, dtype=float)
            gravity = self.model.joint_torques(q, np.zeros_like(q), np.zeros_like(q))
            self.residual.signals.offset = np.asarray(tau_j, dtype=float) - gravity
            self._offset0 = self.residual.signals.offset.copy()
            if self.offsets is not None:
                self.offsets.reset()
                self.residual.offset_var = self.offsets.var
            self.residual.reset()

    def recent_external(self) -> np.ndarray | None:
        return self.events.recent_external()

    def on_meshes(self, ev: ContactEvent, q, shell=None, wrench=None) -> ContactEvent:
        return self.events.on_meshes(ev, np.asarray(q, dtype=float), shell, wrench)

    def close_contact(self, t_ns: int, probability: float | None = None, *, lost: bool = False) -> ContactEvent:
        """The open contact's offset (:meth:`ContactEvents.close_contact`). ``lost``: closed because a
        stream was lost (flagged ``lost``; the detector and the track start afresh)."""
        if lost:
            self.detector.reset()
        self._last = None
        return self.events.close_contact(t_ns, probability, lost=lost)

    def restart_motion(self) -> None:
        """The joint stream was lost and is back: the observer starts afresh from the next sample."""
        self.residual.reset()
        self._last = None
        self.events.previous = None


class FlangeWrench:
    """A flange F/T sensor's reading as the contact's wrench: the tool's own loads beyond the sensor's site
    taken away (:class:`~ftc_hw.compensation.Compensator` on the model, whose sensor sits at that site and so
    carries only the bodies beyond it), turned into the wrench on the arm (sensor frame, about its origin).
    Its covariance: the sensor's noise plus the detection's ``extra_cov``."""

    def __init__(self, scene: Scene, model: ArmModel, settings: PipelineSettings) -> None:
        c, extra = settings.corrections, settings.detection.extra_cov
        self.compensator = Compensator(model, "dynamics", c.bias, gain=c.gain, frame=c.frame,
                                       contact_gain=c.contact_gain)
        self.sign = -scene.sensor.reading_sign  # the reading's change -> the contact's wrench on the arm
        self.cov = scene.sensor.noise_cov + (0.0 if extra is None else np.reshape(extra, (6, 6)))
        self._missing = np.diag(np.full(6, 1e12))  # a frame without a reading: its wrench says nothing

    def contact(self, raw, q, qd, qdd) -> np.ndarray | None:
        """The contact's wrench (6,) from this frame's reading, None when there is none (or not finite)."""
        if raw is None:
            return None
        raw = np.asarray(raw, dtype=float)
        if raw.shape != (6,) or not math.isfinite(float(raw.sum())):
            return None
        return self.sign * self.compensator.external(raw, q, qd, qdd)

    def stacked(self, r: np.ndarray, cov: np.ndarray, w: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """[r, w] and its block-diagonal covariance: the detector's statistic over both signals."""
        n = r.size
        out, big = np.zeros(n + 6), np.zeros((n + 6, n + 6))
        out[:n], big[:n, :n] = r, cov
        if w is None:
            big[n:, n:] = self._missing
        else:
            out[n:], big[n:, n:] = w, self.cov
        return out, big


def pipeline_for(scene: Scene, settings: PipelineSettings | None = None, *,
                 clock: StageClock = NO_CLOCK) -> ContactPipeline | JointContactPipeline:
    """ContactPipeline where the scene uses a base F/T sensor, else JointContactPipeline (joint signals,
    with a flange sensor's wrench where used)."""
    if scene.sensing.ft == "base":
        return ContactPipeline(scene, settings, clock=clock)
    return JointContactPipeline(scene, settings, clock=clock)


def link_subspaces(model: ArmModel, scene: Scene, dims: int) -> tuple[int, ...] | None:
    """The leading blocks of the tested vector ([r] or [r, w]) a contact on each touchable link can load:
    its moving joints (the first k of a serial chain), everything (``dims``) where a flange sensor sees the
    link; ``dims`` always (a contact off the declared links). None where some link's joints are not the
    first k (a coupling): the full test alone."""
    out = {dims}
    flange = dims > scene.n_joints
    for t in scene.touchable:
        mask = model.moving_joints(t.link)
        k = int(mask.sum())
        if k == 0:
            continue  # no joint moves it (the base): no joint signal sees it
        if not mask[:k].all():
            return None
        out.add(dims if flange and sensor_sees(model, t.link) else k)
    return tuple(sorted(out))


def sensor_sees(model: ArmModel, link: str) -> bool:
    """Whether the model's F/T sensor carries ``link`` (the link hangs beyond the sensor's body; every
    link for a sensor under the base)."""
    if model.sensor_body is None:
        return False
    m, body = model.model, model.model.body(link).id
    while body not in (0, model.sensor_body):
        body = int(m.body_parentid[body])
    return body == model.sensor_body


def add_rotor_inertia(model: ArmModel, rotor: np.ndarray) -> None:
    """Each scene joint's identified rotor inertia (kg m^2, at the joint) onto the model's armature (the dof
    its motor drives: a coupling's first driven joint, as ``rotor / ratio^2`` in that dof's units)."""
    jm = model.joints
    dofs, ratio = jm.dadr[jm.lead], jm.ratio[jm.lead]
    model.model.dof_armature[dofs] += rotor / ratio**2


def _finite(q: np.ndarray, qd: np.ndarray, signal, n: int) -> bool:
    if signal is None or q.shape != (n,) or qd.shape != (n,):
        return False
    s = np.asarray(signal, dtype=float)
    return s.shape == (n,) and math.isfinite(float(q.sum() + qd.sum() + s.sum()))


def _idle(detector: JointDetector, d2: float = 0.0) -> Detection:
    """The detector's state for a frame it did not judge."""
    return Detection(detector.active, d2, False, 0.0, None, detector.onset_t_ns)


def _link_probability(e: ContactEstimate) -> float:
    """The chosen link's posterior probability (the estimate's first candidate row's score: its log)."""
    if not e.candidate_links or e.candidate_data.shape[0] == 0:
        return 0.0
    return min(1.0, max(0.0, float(math.exp(e.candidate_data[0, 6]))))
