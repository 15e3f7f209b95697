"""The per-frame contact pipeline: raw wrench and joint state in; external wrench, detection,
estimate and contact events out. The live monitor, replay and the benchmarks all run this.
"""
from __future__ import annotations

import functools
import math
from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from .bus import ContactEvent
from .compensation import Compensator, JointResiduals, ModelError, OnlineRefiner, QddEstimator, RecentPeak
from .compensation.kernels import lag_rows, qdd_step
from .detection import ContactDetector, Detection
from .detection.kernels import mahalanobis2, quad_sum, window_change
from .model import ArmModel, Payload
from .model.arm import link_reach
from .model.inertials import skew
from .model.mesh_surface import MeshShell, pipeline_mesh_shell
from .scene import CompensationLevel, Scene
from .solver import ContactEstimate, Solver, make_solver
from .tracking import FUSED_FLAGS, ContactTrack, fuse_point, link_pose, report

G_REFRESH_NS = 10_000_000
QDD_RING = 64
LAG_WINDOW_SAMPLES = 3  # the lag window spans at least this many sensor samples
# an arm's reaction to a contact that counts against the sensor noise (chi-square, 1 dof, p = 0.999)
IMPACT_CHI2 = 10.83
IMPACT_PASSES = 2


@dataclass(frozen=True, slots=True)
class FrameResult:
    t_ns: int
    external: np.ndarray  # external contact wrench, sensor frame, scene convention
    detection: Detection
    estimate: ContactEstimate | None  # while in contact
    tau_ext: np.ndarray | None  # J^T p from the currents, N m
    events: tuple[ContactEvent, ...]


@dataclass
class _ContactRun:
    """The open (or last) contact: its id, its figures so far and its last event with an estimate."""

    contact_id: int = 0
    onset_ns: int = 0
    last_ns: int = 0
    peak: float = 0.0
    impulse: float = 0.0
    last_event: ContactEvent | None = None  # the last with an estimate
    last_trusted: ContactEvent | None = None  # the last whose estimate the track would fuse (flags: grazing)
    onset_link: str = ""

    def add(self, t_ns: int, external: np.ndarray) -> None:
        f = math.sqrt(float(external[0] ** 2 + external[1] ** 2 + external[2] ** 2))
        self.impulse += f * max(t_ns - self.last_ns, 0) * 1e-9
        self.peak = max(self.peak, f)
        self.last_ns = t_ns

    def stamp(self, ev: ContactEvent, final: bool = False, **changes: np.ndarray) -> ContactEvent:
        """``ev`` with the contact's id and figures (and ``changes`` to its fields)."""
        out = replace(ev, contact_id=self.contact_id, duration_s=max(ev.t_host_ns - self.onset_ns, 0) * 1e-9,
                      peak_force=self.peak, impulse=self.impulse, **changes)
        if not final and "no_estimate" not in ev.flags:
            self.last_event = out
            if FUSED_FLAGS.issuperset(f for f in ev.flags if f != "uncertain"):
                self.last_trusted = out
        return out


class ContactPipeline:
    """One scene's compensation, detection and localization. Not thread-safe: one per reader thread."""

    def __init__(self, scene: Scene, *, level: CompensationLevel | None = None, bias=None,
                 payload: Payload | None = None, method: str = "ours", use_currents: bool = True,
                 p_false: float = 1e-9, n_on: int = 2, n_off: int = 5, update_period_s: float = 0.02,
                 qdd_tau: float = 0.002, extra_cov=None, track_slide: float | None = 0.01,
                 bias_var_ratio: float = 0.01, impact_window_s: float | None = 0.005,
                 flag_uncertain: bool = True, gap_hold_s: float | None = 0.1, gain=None, contact_gain=None,
                 inertials=None, frame=None, gravity=None, joints=None, model_error=None,
                 refine: bool = False, surface: str = "meshes") -> None:
        """Calibrated corrections (``Calibration.pipeline_kwargs``): ``gain`` the sensor's linear error
        (applied to the arm's loads), ``contact_gain`` what of it is undone on the contact's wrench (the
        identification's told terms; None: ``gain``), ``inertials`` link inertial corrections, ``frame``
        the sensor's true frame (a mount yaw), ``gravity`` a tilted gravity vector (m/s^2, base frame),
        ``joints`` identified ``torque_constant``, ``friction_viscous``, ``friction_coulomb`` (per joint),
        ``model_error`` the identification's parameter covariance (:class:`~ftc_hw.compensation.ModelError`).
        ``refine``: with a ``model_error``, keep refining the identified parameters while the arm moves free
        (:class:`~ftc_hw.compensation.OnlineRefiner`; ``refiner.drift()`` says how far they moved).
        ``surface``: ``meshes`` puts each event's point where its line of action enters the touched
        link's meshes, where the scene has them (:func:`~ftc_hw.model.mesh_surface.pipeline_mesh_shell`;
        ``surface_source`` says which); ``primitives`` leaves it on the solver's primitives."""
        self.scene = scene
        model_scene = scene if gravity is None else replace(scene, gravity=np.asarray(gravity, dtype=float))
        if joints:
            model_scene = replace(model_scene, robot=replace(
                model_scene.robot, **{k: np.asarray(v, dtype=float) for k, v in joints.items()}))
        model = ArmModel(model_scene, payload, inertials)
        self.compensator = Compensator(model, level, bias, gain=gain, frame=frame, contact_gain=contact_gain)
        self.identified_error = None if model_error is None else ModelError.from_kwargs(model, model_error)
        self.refiner = (OnlineRefiner(self.compensator, self.identified_error, scene.sensor.noise_cov)
                        if refine and self.identified_error is not None else None)
        self.level = self.compensator.level
        self.solver: Solver = make_solver(model, method)
        self.residuals = JointResiduals(model_scene) if use_currents else None
        self.qdd = QddEstimator(scene.n_joints, qdd_tau)
        self.extra_cov = None if extra_cov is None else np.asarray(extra_cov, dtype=float).reshape(6, 6)
        cov = scene.sensor.noise_cov + (np.zeros((6, 6)) if self.extra_cov is None else self.extra_cov)
        self.detector = ContactDetector(cov, p_false=p_false, n_on=n_on, n_off=n_off)
        self.update_period_ns = int(update_period_s * 1e9)
        self._last_update_ns = 0
        self._last_estimate: ContactEstimate | None = None
        self._contact = _ContactRun()
        # events carry the contact's point fused over its frames (None: each frame's own estimate)
        self.track = (None if track_slide is None else
                      ContactTrack(model, slide=track_slide, body_poses=self.solver.body_poses))
        self._solved_poses = self.solver.solved_body_poses  # the kinematics of the frame just solved, if any
        self._prev: tuple | None = None  # the last frame's (t_ns, external, q, model_error, saturated)
        if self.track is not None:
            # a bias given (calibration file, scene) is taken as known to a tenth of one sample's noise
            self.track.set_bias(bias_var_ratio)
        # the recent acceleration estimates (a ring: enough rows for the lag window at 7 kHz)
        self._qdd_ring = np.zeros((QDD_RING, scene.n_joints))
        self._qdd_ring_t = np.full(QDD_RING, -1, dtype=np.int64)
        self._qdd_next = 0
        self._qdd_change = np.zeros(scene.n_joints)
        self._g_cache: np.ndarray | None = None
        self._g_rows = np.zeros((scene.n_joints, 6))  # _g_cache transposed, C-ordered
        self._g_time = 0
        self._lag_window_ns = int(2 * qdd_tau * 1e9)
        # The acceleration estimate lags by about a sample at a slow sensor's rate: the detector's window
        # holds a few samples, or a change one sample back is forgotten while the wrench still shows it
        # (a joint sticking at a reversal on dxl-arm, 100 Hz: 2 tau = 4 ms saw one step, a 7-sigma
        # alarm). The solver keeps 2 tau: a longer one cost dxl-arm's ideal p95 4.7 -> 6.5 mm.
        self._judge_window_ns = max(self._lag_window_ns, round(LAG_WINDOW_SAMPLES / scene.sensor.rate_hz * 1e9))
        self._judge_change = np.zeros(scene.n_joints)
        # how long after a contact's start the estimated acceleration may still miss the arm's
        # reaction to it (None: never re-weigh; see _impact_solve)
        self.impact_window_ns = None if impact_window_s is None else int(impact_window_s * 1e9)
        self._noise_inv = np.linalg.inv(scene.sensor.noise_cov)
        self._kt = np.asarray(model_scene.robot.torque_constant, dtype=float)
        self._pre_current: deque[np.ndarray] = deque(maxlen=3)  # the last frames before a contact
        self._impact_dtau: np.ndarray | None = None
        self._impact_seed: ContactEstimate | None = None  # the last impact estimate of this contact
        # an event whose point is less certain than the touched link is big says nothing of where
        self._link_reach = link_reach(model) if flag_uncertain else None
        # m, 1 sigma per link (the scene's, and a mesh fit's), looked up once per link
        self._surface = functools.cache(model.surface_tolerance)
        if surface not in ("meshes", "primitives"):
            raise ValueError(f"surface: expected 'meshes' or 'primitives', got {surface!r}")
        self.mesh_shell = pipeline_mesh_shell(scene) if surface == "meshes" else None
        self.surface_source = "meshes" if self.mesh_shell is not None else "primitives"
        # the contact's external wrench over the last update period: the line of action followed into the meshes
        # (a ring and its running sum: np.mean over a deque took 22 us an event, measured by ftc bench pipeline)
        self._recent_ring = np.zeros((max(1, round(update_period_s * scene.sensor.rate_hz)), 6))
        self._recent_sum = np.zeros(6)
        self._recent_count = 0
        self._gain_std = gain_std_of(scene)
        self._gain_var = self._gain_std**2
        self._k_work = np.empty((3, 6))  # _systematic's point-from-wrench map
        self._sensor_pose = model.base_T_sensor
        self.lag_floor = 0.02  # rad/s^2: below, the lag's wrench error is a fraction of the sensor noise
        self.lag_gain = 3.0  # the lag error exceeds the change over the window: 3 covers it with margin
        # Joint state interpolated over missed joint samples hides the motion in between: a transient
        # under way (a joint's friction flipping at a reversal rings for ~90 ms on ur5e) goes on
        # unseen, and its wrench reads as a contact. Over such a gap the lag error is taken as the
        # largest seen in the gap plus gap_hold_s before it (measured: 16 ms gaps placed anywhere in
        # a reversal gave d2 up to 1100, 20x the onset threshold; with the hold, none above 22).
        # None: never widen.
        self.gap_hold_ns = None if gap_hold_s is None else int(gap_hold_s * 1e9)
        self._lag_peak = RecentPeak(scene.n_joints)
        self._gap_until = -1  # the hold lasts until then (the estimate's clock, ns)
        self._gap_span = 0
        self._warm_up()

    def _warm_up(self) -> None:
        """Call every compiled kernel once now. numba loads each from its cache on its first call,
        tens of milliseconds that the first contact would otherwise wait for, and its reflex stop
        with it (measured: 28-32 ms from the onset sample to the stop, 3-6 ms once loaded)."""
        n = self.scene.n_joints
        row = np.zeros((1, 6))
        mahalanobis2(np.zeros(6), self.detector.cov, row)
        quad_sum(row, self.detector.inv)
        window_change(self._qdd_ring, self._qdd_ring_t, 0, self._lag_window_ns, np.zeros(n), self._qdd_change)
        qdd_step(np.zeros(n), np.zeros(n), np.zeros(n), 0.5, 1e-3, np.zeros(n))
        lag_rows(self._g_rows, np.zeros(n), 1.0)
        if self.residuals is not None:
            self.residuals.external_torques(np.zeros(n), np.zeros(n), np.zeros(n))
        self.solver.solve(np.array([0.0, 0.0, 10.0, 0.0, 0.0, 0.0]), np.asarray(self.scene.robot.home, dtype=float),
                          tau_ext=np.zeros(n), tau_std=np.ones(n), extra_cov=np.zeros((6, 6)))
        poses = (np.zeros((2, 3)), np.ones((2, 4)))
        fuse_point(np.zeros(3), np.eye(3), np.zeros(3), np.eye(6), *poses, 1, 0.0, 0.0, 1.0, np.zeros((4, 3)),
                   np.zeros((3, 4)))
        link_pose(*poses, 1, np.zeros((3, 4)))
        report(np.zeros(3), np.eye(3), np.zeros((4, 3)), 0.0, np.zeros((3, 4)), np.zeros(3), np.zeros((3, 3)))

    def tare(self, raw_mean, q, samples: int, t_ns: int) -> None:
        """Re-zero on the mean ``raw_mean`` of ``samples`` still, untouched frames at joint angles q
        (taken by host time ``t_ns``): the bias is then known to 1/samples of the sensor's noise."""
        zero = np.zeros(self.scene.n_joints)
        self.compensator.tare(raw_mean, q, zero, zero)
        if self.identified_error is not None:
            self.identified_error.set_tare(q)
        if self.refiner is not None:
            self.refiner.set_tare(raw_mean, q)
        if self.track is not None:
            self.track.set_bias(1.0 / max(int(samples), 1), t_ns)

    def process(self, t_ns: int, raw, q, qd=None, current=None, qdd=None, saturated: bool = False,
                t_device_ns: int | None = None, joint_gap_ns: int = 0) -> FrameResult:
        """One F/T sample at host time t_ns with the joint state at that time. ``t_device_ns``: the
        sample's device time, the steadier clock for differentiating qd (else t_ns is used).
        ``joint_gap_ns``: > 0 when that joint state was interpolated (or extrapolated) over missed
        joint samples: the span, ns, between the samples it was made from."""
        q = np.asarray(q, dtype=float)
        need_dyn = self.level == "dynamics"
        if need_dyn and qd is None:
            raise ValueError("dynamics compensation needs the joint velocities qd")
        lag_error = judge_lag = held = None
        qdd_estimated = need_dyn and qdd is None
        if qdd_estimated:
            t_clock = t_ns if t_device_ns is None else t_device_ns
            qdd = self.qdd.update(t_clock * 1e-9, qd)
            lag_error, judge_lag = self._lag_errors(t_clock, qdd)
            held = self._gap_held(t_clock, lag_error, joint_gap_ns)
        want_tau = self.residuals is not None and current is not None
        # the joint torques come free with the inverse dynamics; at the gravity level they cost an
        # extra pass, paid only in contact (below)
        loads, model_tau = self.compensator.loads(q, qd, qdd, joint_torques=want_tau and need_dyn)
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
        det = self.detector.update(t_ns, external, judged)
        self._impact_dtau = None
        if current is not None and qdd_estimated:
            if not det.active:
                self._pre_current.append(np.asarray(current, dtype=float))
            elif self._pre_current:
                # the joint controllers' reaction since before the contact, in torque
                self._impact_dtau = self._kt * (np.asarray(current, dtype=float) - self._pre_current[0])
        tau_ext = tau_std = None
        if want_tau and det.active:  # only the solver needs them
            if model_tau is None:
                model_tau = (self.compensator.loads(q, qd, qdd, joint_torques=True)[1]
                             if self.level == "gravity" else np.zeros(self.scene.n_joints))
            tau_ext, tau_std = self.residuals.external_torques(model_tau, current,
                                                               qd if qd is not None else np.zeros_like(q))
        events: list[ContactEvent] = []
        estimate = None
        if det.active or det.change == "offset":
            if det.active:
                impact = qdd_estimated and self._in_impact(det, t_ns)
                if det.change == "onset":
                    self._impact_seed = None
                if self.track is not None and det.change == "onset":
                    self.track.reset()
                    if not impact:
                        self._track_onset_start(det, tau_ext, tau_std)
                estimate = self._solve(external, q, tau_ext, tau_std, saturated, model_error, impact)
                self._last_estimate = estimate
                if self.track is not None:
                    self.track.update(t_ns, estimate, q, self._solved_poses())
            events.extend(self._contact_events(t_ns, det, estimate, external, q))
        if self.track is not None:
            self._prev = (t_ns, external, q.copy(), model_error, saturated)
        if self.refiner is not None and qd is not None and qdd is not None:
            if det.active or det.change == "offset" or saturated:
                self.refiner.touched(t_ns)
            elif det.d2 < 0.5 * self.detector.on:  # clearly nothing touching (a rising contact stays out)
                self.refiner.observe(t_ns, external, q, qd, qdd)
        return FrameResult(t_ns, external, det, estimate, tau_ext, tuple(events))

    def _contact_events(self, t_ns: int, det: Detection, estimate: ContactEstimate | None,
                        external: np.ndarray, q: np.ndarray) -> list[ContactEvent]:
        """This frame's onset, update or offset, stamped with the contact's id and figures."""
        track = self.track if self.track is not None and self.track.active else None
        if det.change == "onset":
            onset = det.onset_t_ns or t_ns
            self._contact = _ContactRun(self._contact.contact_id + 1, onset, onset)
            self._contact.add(t_ns, external)
            self._recent_count = 0
            self._recent_sum[:] = 0.0
            self._add_recent(external)
            self._last_update_ns = t_ns
            ev = self._event(onset, "onset", estimate, det.probability, track, self._link_reach)
            self._contact.onset_link = ev.link
        elif det.change == "offset":
            return [self.close_contact(t_ns, det.probability)]
        else:
            self._contact.add(t_ns, external)
            self._add_recent(external)
            if t_ns - self._last_update_ns < self.update_period_ns:
                return []
            ev = self._event(t_ns, "update", estimate, det.probability, track, self._link_reach)
            self._last_update_ns = t_ns
        return [self._contact.stamp(ev, **self._shipping(ev, external, q))]

    def _shipping(self, ev: ContactEvent, external: np.ndarray, q: np.ndarray) -> dict[str, np.ndarray]:
        """What changes in the event as it goes out: its point's uncertainty with the systematic errors
        (:meth:`_systematic`), then its point on the meshes along the recent wrench's line (:meth:`on_meshes`).
        The frame's sensor pose is shared, and the changes go into the stamped event: one new event
        instead of three (an event frame's thread CPU 297 -> 217 us, median, with the pose kept per q;
        docs/measurements/monitor.md)."""
        if "no_estimate" in ev.flags:
            return {}
        b_T_s = self._sensor_pose(q)
        std = self._systematic(ev, external, b_T_s)
        moved = self._mesh_point(ev, q, std, None, self.recent_external(), b_T_s)
        if moved is not None:
            return {"point": moved[0], "point_std": moved[1]}
        return {} if std is ev.point_std else {"point_std": std}

    def _systematic(self, ev: ContactEvent, external: np.ndarray, b_T_s: np.ndarray) -> np.ndarray:
        """The event's point uncertainty with what no number of frames averages away: the real shell's
        distance from the model's (the touched link's surface tolerance, every axis) and the sensor's gain and
        crosstalk error on the contact's own wrench (``gain_std``: 1 sigma per entry), carried to the
        point across the force's line: ``dc = ([f]x dm - [f]x [c]x df) / |f|^2`` (sensor frame; ``b_T_s``
        the sensor's pose). Its ``point_std`` itself where the event has no force."""
        f = np.asarray(ev.force, dtype=float)
        f2 = float(f @ f)
        if f2 == 0.0:
            return ev.point_std
        r = b_T_s[:3, :3]
        f_s, c_s = r.T @ f, r.T @ (np.asarray(ev.point, dtype=float) - b_T_s[:3, 3])
        sigma_w = np.sqrt(self._gain_var @ (np.asarray(external, dtype=float) ** 2))  # per wrench axis
        k = self._k_work
        k[:, 3:] = skew(f_s)
        k[:, :3] = -k[:, 3:] @ skew(c_s)
        k /= f2
        cov = r @ (k * sigma_w**2) @ k.T @ r.T
        var = np.maximum(cov.diagonal(), 0.0)
        var += self._surface(ev.link) ** 2
        return np.sqrt(np.asarray(ev.point_std, dtype=float) ** 2 + var)

    def recent_external(self) -> np.ndarray | None:
        """The open contact's external wrench (sensor frame) averaged over the last update period."""
        n = min(self._recent_count, len(self._recent_ring))
        return self._recent_sum / n if n else None

    def _add_recent(self, external: np.ndarray) -> None:
        k = self._recent_count % len(self._recent_ring)
        if self._recent_count >= len(self._recent_ring):
            self._recent_sum -= self._recent_ring[k]
        self._recent_ring[k] = external
        self._recent_sum += self._recent_ring[k]
        self._recent_count += 1

    def on_meshes(self, ev: ContactEvent, q: np.ndarray, shell: MeshShell | None = None,
                  wrench: np.ndarray | None = None) -> ContactEvent:
        """The event with its point where the contact's line of action enters its link's meshes
        (``shell``, else the pipeline's own; unchanged where there are none or the line misses them).
        The line is the one ``wrench`` (external, sensor frame, e.g. :meth:`recent_external`) acts
        along, taken where it passes closest to the event's point: the solver's point lies on the
        primitives, and where the real shell stands out of them the true line misses them, so the
        solver's point is off it. Without a wrench: the line through the event's point along its force.
        In the point's uncertainty the real shell's distance from the meshes (the vendor's tolerance,
        or the scene's ``surface_tolerance_m`` for its own meshes) takes the place of its distance from
        the primitives (``surface_tolerance_m`` and a mesh fit's RMS; :meth:`_systematic`)."""
        if "no_estimate" in ev.flags:
            return ev
        moved = self._mesh_point(ev, q, ev.point_std, shell, wrench, None)
        return ev if moved is None else replace(ev, point=moved[0], point_std=moved[1])

    def _mesh_point(self, ev: ContactEvent, q: np.ndarray, point_std: np.ndarray, shell: MeshShell | None,
                    wrench: np.ndarray | None, b_T_s: np.ndarray | None) -> tuple[np.ndarray, np.ndarray] | None:
        """:meth:`on_meshes`' point and its std (the event's being ``point_std``); None: unchanged.
        ``b_T_s``: the sensor's pose at q where the caller has it."""
        shell = shell or self.mesh_shell
        if shell is None:
            return None
        point, force = np.asarray(ev.point, dtype=float), np.asarray(ev.force, dtype=float)
        f_s = None if wrench is None else np.asarray(wrench[:3], dtype=float)
        if f_s is not None and float(f_s @ f_s) > 0.0:
            if b_T_s is None:
                b_T_s = self._sensor_pose(q)
            on_line = b_T_s[:3, :3] @ (_cross(f_s, wrench[3:]) / float(f_s @ f_s)) + b_T_s[:3, 3]
            force = b_T_s[:3, :3] @ f_s
            u = force / np.linalg.norm(force)
            point = on_line + float((point - on_line) @ u) * u
        entry = shell.entry(ev.link, q, point, force)
        if entry is None:
            return None
        surface = self._surface(ev.link)
        var = np.asarray(point_std, dtype=float) ** 2 - surface**2
        return entry, np.sqrt(np.maximum(var, 0.0) + shell.tolerance.get(ev.link, surface) ** 2)

    def restart_motion(self) -> None:
        """The joint stream was lost and is back: what was estimated from its past (the acceleration,
        the currents before a contact, the last frame) starts afresh."""
        self.qdd.reset()
        self._qdd_ring_t[:] = -1
        self._pre_current.clear()
        self._prev = None
        self._gap_until = -1

    @property
    def in_contact(self) -> bool:
        return self.detector.active

    def close_contact(self, t_ns: int, probability: float | None = None, *, lost: bool = False) -> ContactEvent:
        """The open contact's offset at host time t_ns: its last estimate (as its last onset or update
        with a sound estimate said, one the track would fuse; else its last with any estimate; else the
        last frame's own) with its duration, peak force and impulse; flagged ``relinked`` when that
        names another link than the onset did.
        ``lost``: closed because a stream was lost (flagged ``lost``; the detector and the track start
        afresh). ``probability``: the offset frame's (default: the last event's)."""
        run = self._contact
        # a contact's last low-force or ambiguous estimate (its release) says less than its last sound one
        last = run.last_trusted or run.last_event
        if last is None:
            last = self._event(t_ns, "offset", self._last_estimate, probability or 0.0)
        # the track settled on another link than the onset's provisional estimate: said, not hidden
        flags = (*last.flags, *(("relinked",) if last.link != run.onset_link else ()), *(("lost",) if lost else ()))
        p = last.probability if probability is None else probability
        ev = run.stamp(ContactEvent.make(t_ns, "offset", last.link, last.point, last.force, last.point_std,
                                         flags=flags, probability=p), final=True)
        self._last_estimate = None
        if lost:
            self.detector.reset()
        if self.track is not None:
            self.track.reset()
        return ev

    def _extra(self, model_error: np.ndarray | None) -> np.ndarray | None:
        """The compensation's own uncertainty for a frame: the acceleration estimate's lag error weighs
        on the fit as it does on detection."""
        extra = self.extra_cov
        if model_error is not None:
            extra = model_error.T @ model_error if extra is None else extra + model_error.T @ model_error
        return extra

    def _in_impact(self, det: Detection, t_ns: int) -> bool:
        return (self.impact_window_ns is not None and det.onset_t_ns is not None
                and t_ns - det.onset_t_ns <= self.impact_window_ns)

    def _solve(self, external, q, tau_ext, tau_std, saturated: bool, model_error, impact: bool) -> ContactEstimate:
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
        model = self.compensator.model
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

    def _track_onset_start(self, det: Detection, tau_ext, tau_std) -> None:
        """The onset goes out at the detector's n_on-th sample above the threshold; the sample before
        it, already above, is fused first (with this frame's joint torques: they change slowly), so
        the onset's point rests on two frames instead of one. Costs one solve, at onsets only; none
        in an impact, whose estimates the track does not fuse."""
        prev = self._prev
        if prev is None or det.onset_t_ns is None or prev[0] < det.onset_t_ns:
            return
        t_prev, external, q, model_error, saturated = prev
        e = self._solve(external, q, tau_ext, tau_std, saturated, model_error, False)
        self.track.update(t_prev, e, q, self._solved_poses())

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

    def _gap_held(self, t_clock: int, lag_error: np.ndarray | None, joint_gap_ns: int) -> np.ndarray | None:
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
            self._gap_until = t_clock + 5 * self._lag_window_ns // 2
            self._gap_span = joint_gap_ns
        if t_clock > self._gap_until or self.detector.active:
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
        i = self._qdd_next
        solver = self._lag_over(t_ns, qdd, self._lag_window_ns, self._qdd_change)
        judge = (solver if self._judge_window_ns == self._lag_window_ns
                 else self._lag_over(t_ns, qdd, self._judge_window_ns, self._judge_change))
        self._qdd_ring[i] = qdd
        self._qdd_ring_t[i] = t_ns
        self._qdd_next = (i + 1) % QDD_RING
        return solver, judge

    def _lag_over(self, t_ns: int, qdd: np.ndarray, window_ns: int, change: np.ndarray) -> np.ndarray | None:
        biggest = window_change(self._qdd_ring, self._qdd_ring_t, t_ns, window_ns, qdd, change)
        return None if self.lag_gain * biggest < self.lag_floor else self.lag_gain * change

    @staticmethod
    def _event(t_ns: int, kind: str, e: ContactEstimate | None, probability: float,
               track: ContactTrack | None = None, reach: dict[str, float] | None = None) -> ContactEvent:
        """The event always goes out (an onset above all). With a track, its point is the contact's
        fused point and the frame's estimate gives the force and flags; otherwise the frame's own
        estimate, and one it cannot carry (none, no contact, no link or a non-finite value) gives
        zeros and the ``no_estimate`` flag. ``reach``: per link, the size beyond which a point's
        uncertainty (the norm of its standard deviations) says nothing of where on the link it is:
        such an event is flagged ``uncertain``."""
        if track is not None:
            force = e.force if e is not None and math.isfinite(float(e.force.sum())) else np.zeros(3)
            point, std = track.point_and_std()
            flags = _with_uncertain(e.flags if e is not None else (), track.link, std, reach)
            return ContactEvent.make(t_ns, kind, track.link, point, force, std, flags=flags,
                                     probability=probability)
        if e is not None and e.contact and e.link:
            std = e.point_std
            if math.isfinite(float(e.point.sum() + e.force.sum() + std.sum())):
                return ContactEvent.make(t_ns, kind, e.link, e.point, e.force, std,
                                         flags=_with_uncertain(e.flags, e.link, std, reach),
                                         probability=probability)
        z = np.zeros(3)
        flags = (*e.flags, "no_estimate") if e is not None else ("no_estimate",)
        link = e.link if e is not None and e.link else "unknown"
        return ContactEvent.make(t_ns, kind, link, z, z, z, flags=flags, probability=probability)


def gain_std_of(scene: Scene) -> np.ndarray:
    """1 sigma of each entry of the sensor's linear error on a contact's wrench (6 x 6): the scene's
    ``sensor.accuracy`` (relative; an off-diagonal term scaled by the two axes' ranges, as crosstalk is
    specified in per cent of full scale). Not the identification's posterior, though the identified gain
    is undone on the contact's wrench: what free motion tells of the gain leans on the link masses it
    fits beside and on the arm's own loads (its weight along z, the moments of gravity), and its
    posterior under-covered (measured, ur5e typical: coverage 0.77 with the posterior, 0.89 with the
    accuracy)."""
    rng = np.asarray(scene.sensor.range, dtype=float)
    return scene.sensor.accuracy * rng[:, None] / rng[None, :]


def _with_uncertain(flags: tuple[str, ...], link: str, std: np.ndarray,
                    reach: dict[str, float] | None) -> tuple[str, ...]:
    size = None if reach is None else reach.get(link)
    if size is None or float(np.linalg.norm(std)) <= size:
        return tuple(flags)
    return (*flags, "uncertain")


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` of two 3-vectors, the same products and differences, without its axis handling
    (15 us a call against 1, measured hot)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])
