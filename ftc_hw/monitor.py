"""The contact pipeline on the bus: every F/T frame, with the joint state interpolated at its
timestamp, goes through compensation, detection and localization; contact events go back on the bus.

Timestamps: frames that carry device time are placed on the host clock through each source's
``ClockAligner`` (a minimum-delay filter), so the F/T and joint streams line up without the jitter of
their delivery; frames without device time use their host receive time.

A worker thread owns the pipeline (a bounded queue decouples it from the F/T reader: a slow pipeline
drops frames, counted, instead of stalling the device). Without a calibration the sensor is tared
on the first ``tare_s`` of frames, which must be taken with the arm still and untouched. A frame
received more than 50 ms after its aligned time counts as late (``ft_frames_late``: a backlog between
the device and the monitor, or, with emulated devices, a simulated world running behind real time;
the clock alignment keeps such frames at their true time). A frame judged more than 50 ms after its
adapter received it counts in ``ft_frames_backlog``: the monitor itself fell behind.

A frame whose joint state had to be made across missed joint samples (the samples around it more
than 1.5 joint periods apart, the period being the stream's median spacing) carries that span as
``joint_gap_ns`` (counted: ``joint_gap_frames``): the motion in between is unknown, and the pipeline
widens the compensation's uncertainty over it.

A stream that stops is a state, not a silence: when no F/T frame has arrived for ``ft_lost_s`` (or no
joint frame for ``arm_lost_s``) the monitor publishes ``DeviceEvent(kind="sensor_lost")`` (or
``"arm_lost"``) on ``events/device`` and closes an open contact with an offset flagged ``lost``;
while the joint stream is lost every F/T frame is dropped unjudged (``blind_frames``: no joint state,
no contact can be told from the arm's own motion). ``sensor_back`` / ``arm_back`` when frames flow
again; the acceleration estimate restarts then. ``lost`` (the streams lost now), ``losses`` (a list of
(stream, host ns lost, host ns back or None)) and the counters ``sensor_lost``, ``arm_lost``,
``blind_frames`` keep the record.

What the pipeline consumes for each F/T frame (its aligned time, the raw wrench, the joint state
interpolated there, whether it went to the tare) is published on ``monitor/input`` as a
:class:`PipelineInput`: the alignment and interpolation depend on arrival order and thread timing,
so a recording keeps their result and a replay feeds it to :meth:`LiveMonitor.consume`, which
reproduces the events exactly.
"""
from __future__ import annotations

import queue
import threading
import time
from collections import Counter, deque
from dataclasses import dataclass, replace

import numpy as np

from .bus import (
    EVENTS_CONTACT,
    EVENTS_DEVICE,
    Bus,
    ClockAligner,
    DeviceEvent,
    SamplingPolicy,
    StateHistory,
    WrenchFlag,
    joints_topic,
    wrench_topic,
)
from .pipeline import FrameResult, PipelineSettings, pipeline_for
from .pipeline.contact import ContactPipeline
from .pipeline.limits import LimitAssessor
from .pipeline.provisional import ProvisionalJudge, ProvisionalLedger
from .scene import Scene
from .scene.limits import CellLimits

MONITOR_INPUT = "monitor/input"
MONITOR_JUDGED = "monitor/judged"
LATE_NS = 50_000_000  # an F/T frame received this long after its (aligned) time counts as late
# an F/T frame judged this long after its adapter received it: the monitor fell behind (a host that
# cannot keep up); the joint wait (max_gap_ms, 20 ms) stays well inside it
BACKLOG_NS = 50_000_000
MAX_BATCH = 256  # F/T frames taken off the queue at once (the rest wait for the next pass)
# confirmed judgements worked off before new frames that wait are taken (and judged provisionally): a new frame's
# provisional judgement waits at most this plus one frame's (0 gave the same stops at 1 kHz: each pass then
# pays its own cost for a frame or two)
YIELD_AFTER_NS = 1_000_000
JOINT_PERIOD_SAMPLES = 64  # the joint period is the median spacing of this many recent samples
LOST_S = 0.25  # default: a stream silent this long is lost (shorter gaps: frames counted no_joint_state)


@dataclass(frozen=True, slots=True, eq=False)
class PipelineInput:
    """One sample as the pipeline consumed it: an F/T sample with the joint state at its time, or (a
    scene sensed without a base F/T sensor) a joint sample with the F/T reading at its time, if used.
    ``t_host_ns``: the sample's aligned host time (the pipeline's ``t_ns``); ``seq``/``source``: the
    driving frame's; ``wrench`` (6,) or, no F/T sensor used, (0,); ``tau_j`` the joint torque sensors'
    reading (N m) where used; ``tare``: it went to the tare."""

    t_host_ns: int
    t_device_ns: int | None
    seq: int
    source: str
    wrench: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    current: np.ndarray
    saturated: bool = False
    tare: bool = False
    joint_gap_ns: int = 0  # > 0: the joint state spans missed joint samples (this long between its samples)
    tau_j: np.ndarray | None = None


@dataclass(frozen=True, slots=True, eq=False)
class JudgedFrame:
    """What the pipeline made of one input (on ``monitor/judged`` when the monitor is asked to publish them:
    ROS outputs, the ROS 2 recording). ``t_host_ns``, ``t_device_ns``, ``seq``, ``source``: the input's;
    ``external`` (6,) the external contact wrench (sensor frame, the scene's sign convention, as
    ``FrameResult.external``); ``d2`` the detection statistic; ``in_contact`` the detector's state."""

    t_host_ns: int
    t_device_ns: int | None
    seq: int
    source: str
    external: np.ndarray
    d2: float
    in_contact: bool


@dataclass(frozen=True, slots=True)
class MonitoredFrame:
    t_host_ns: int
    t_device_ns: int | None
    result: FrameResult


class LiveMonitor:
    """The pipeline on the bus. Which stream drives it follows the scene's sensing: each F/T frame,
    with the joint state at its time, when a base F/T sensor is used (``driver == "ft"``); else each
    joint frame, with the (flange) F/T reading at its time where one is used (``driver == "joints"``:
    motor currents, joint torques). The other stream is the side stream, sampled at the driver's times."""

    def __init__(self, bus: Bus, scene: Scene, *, ft_source: str = "ft", arm_source: str = "arm",
                 tare_s: float | None = 0.1, keep_frames: bool = False, max_gap_ms: float = 20.0,
                 max_extrapolate_ms: float = 5.0, publish_inputs: bool = True, ft_lost_s: float = LOST_S,
                 arm_lost_s: float = LOST_S, settings: PipelineSettings | None = None,
                 publish_judged: bool = False, limits: CellLimits | None = None, provisional: bool = True) -> None:
        """``limits``: judge every contact event against the cell's body limits (None: not judged).
        ``provisional``: F/T-driven, judge each frame at once on the extrapolated joint state too (the
        provisional onset, for the reflex; module docstring)."""
        self.bus = bus
        self.scene = scene
        self.pipeline = pipeline_for(scene, settings)
        self.limits = None if limits is None else LimitAssessor(scene, settings or PipelineSettings(), limits)
        self.sensing = sensing = scene.sensing  # one object: Scene.sensing builds it on every call
        self.driver = "ft" if sensing.ft == "base" else "joints"
        self.uses_ft = sensing.ft is not None
        self.ft_topic = wrench_topic(ft_source)
        self.joint_topic = joints_topic(arm_source)
        # the F/T sensor, or the joint torque sensors' offsets, tared at rest; motor currents take none
        self.tare_s = tare_s if self.uses_ft or sensing.joint_torques else None
        # a frame waits for the side stream to pass it as long as a gap may last: on a loaded host the
        # side reader can be late by several periods, and extrapolating over that span near a reversal
        # of the motion reads as a contact (normally the wait is under a period)
        self.wait_s = max_gap_ms / 1e3
        self.keep_frames = keep_frames
        self.publish_inputs = publish_inputs
        self.publish_judged = publish_judged  # each judged frame on monitor/judged (ROS outputs need them)
        self.frames: list[MonitoredFrame] = []
        self.latest: MonitoredFrame | None = None
        self.counters: Counter[str] = Counter()
        self._sub = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._tare_buf: list[tuple[np.ndarray, np.ndarray, np.ndarray | None]] = []
        self._tare_until_ns: int | None = None
        self.tared = self.tare_s is None
        self._ft_clock = ClockAligner()
        self._arm_clock = ClockAligner()
        policy = SamplingPolicy(int(max_gap_ms * 1e6), "linear", int(max_extrapolate_ms * 1e6))
        # the joint state at each F/T sample: interpolated, or extrapolated a little past the newest
        # joint sample (holding would lag the arm, which the dynamics compensation reads as a contact)
        self.joints = StateHistory(policy, maxlen=4096, period_samples=JOINT_PERIOD_SAMPLES)
        # joint-driven: the F/T reading (6) and its saturation (1) at each joint sample
        self.wrenches = StateHistory(policy, maxlen=4096, period_samples=JOINT_PERIOD_SAMPLES)
        self._side_sub = None
        self._lags: deque[int] = deque(maxlen=20_000)  # ns from a frame's arrival to its judgement
        self.lag_ns = 0  # the newest judged frame's (how far behind its input the monitor is now)
        self._waiting: deque = deque()  # the worker's driving frames waiting for the side stream
        self._driving = "sensor" if self.driver == "ft" else "arm"
        self._side = ("arm" if self.driver == "ft" else "sensor" if self.uses_ft else None)
        self.lost_after_ns = {"sensor": int(ft_lost_s * 1e9), "arm": int(arm_lost_s * 1e9)}
        if not self.uses_ft:
            del self.lost_after_ns["sensor"]
        self._rx_ns: dict[str, int | None] = {"sensor": None, "arm": None}  # host time of the newest frame
        self._side_back_t: int | None = None  # aligned time of the side stream's first sample after a loss
        self._last_driving_t: int | None = None  # joint-driven: the previous joint sample's aligned time
        self.lost: set[str] = set()
        self.losses: list[list] = []  # [stream, t_lost_ns, t_back_ns or None]
        self._source = {"sensor": ft_source, "arm": arm_source}
        # the provisional judgement (F/T-driven, the pipeline's model): beside the pipeline, never changing it
        self.provisional = (ProvisionalJudge(self.pipeline) if provisional and self.driver == "ft"
                            and isinstance(self.pipeline, ContactPipeline) else None)
        self.ledger = ProvisionalLedger() if self.provisional is not None else None

    def backlog(self) -> int: return self._sub.pending if self._sub is not None else 0  # driving frames to take

    @property
    def side(self) -> StateHistory | None:
        """The side stream's history: the joints (F/T-driven), the F/T readings (joint-driven), or None."""
        return self.joints if self._side == "arm" else self.wrenches if self._side == "sensor" else None

    def start(self) -> LiveMonitor:
        if self._thread is None:
            if self.driver == "ft":
                self._side_sub = self.bus.subscribe(self.joint_topic, callback=self.on_joints)
                self._sub = self.bus.subscribe(self.ft_topic, maxsize=4096)
            else:
                if self.uses_ft:
                    self._side_sub = self.bus.subscribe(self.ft_topic, callback=self.on_wrench)
                self._sub = self.bus.subscribe(self.joint_topic, maxsize=4096)
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="contact-monitor", daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        if self._thread is None:
            return
        self._stop.set()
        self._sub.close()
        if self._side_sub is not None:
            self._side_sub.close()
        self._thread.join(timeout=5.0)
        self._thread = None
        prefix = "ft" if self.driver == "ft" else "joint"
        self.counters[f"{prefix}_frames_dropped"] = self._sub.drops
        unjudged = self._sub.pending + len(self._waiting)  # a backlog the run ended with: never judged
        if unjudged:
            self.counters[f"{prefix}_frames_unjudged_at_stop"] = unjudged
        if self._lags:  # from a frame's arrival to its judgement (the recent ones)
            lags = np.array(self._lags) / 1e6
            self.counters["judge_lag_ms_p50"] = round(float(np.median(lags)))
            self.counters["judge_lag_ms_p99"] = round(float(np.percentile(lags, 99)))
        for name, clock in (("ft", self._ft_clock), ("arm", self._arm_clock)):
            if clock.capped:
                self.counters[f"{name}_clock_capped"] = clock.capped

    def __enter__(self) -> LiveMonitor:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _run(self) -> None:
        # A driving frame waits (at most wait_s) until the side stream has passed its time, so the
        # side state is interpolated rather than extrapolated; the onset time does not change.
        # The wait is in the worker's time: frames queued behind a waiting one wait with it.
        # Frames are taken as they queued up, all at once: at 7 kHz the stream checks and the wake-up
        # are paid per batch, not per frame.
        pending: deque = deque()
        self._waiting = pending
        while not self._stop.is_set():
            try:
                batch = [self._sub.get(timeout=0.001 if pending else 0.01)]
                batch += self._sub.drain(MAX_BATCH)
            except queue.Empty:
                batch = []
            except Exception:  # noqa: BLE001 - the subscription was closed: we are stopping
                break
            if batch:
                self.take(pending, batch, time.monotonic())
            self._check_streams()
            self.judge_ready(pending, time.monotonic())

    def take(self, pending: deque, batch: list, arrived: float) -> None:
        """Driving frames received at ``arrived`` (monotonic s) into ``pending``, each judged provisionally at once."""
        clock = self._ft_clock if self.driver == "ft" else self._arm_clock
        late = "ft_frames_late" if self.driver == "ft" else "joint_frames_late"
        for frame in batch:
            t_frame = self._aligned(clock, frame)
            if frame.t_host_ns - t_frame > LATE_NS:  # a backlog between the device and us
                self.counters[late] += 1
            pending.append((arrived, t_frame, frame))
            if self.provisional is not None:
                self._judge_provisional(frame, t_frame)
        self._received(self._driving, pending[-len(batch)][1])  # back (after a loss) from the first

    def judge_ready(self, pending: deque, now: float) -> None:
        """Every pending frame whose side state is there (or that waited ``wait_s`` by ``now``, monotonic s); with
        provisional judgement, for at most YIELD_AFTER_NS while a new driving frame waits: it is taken (and judged
        provisionally) first. A host that cannot keep up builds a backlog of confirmed judgements, and a
        provisional onset queued behind it came that late: a stop's p99 of 21 ms at 1 kHz with 13,703 frames
        judged over 50 ms after they arrived (ur5e, 60 s). On a host that cannot keep up at all (7 kHz here) the
        provisional judgement then runs on every frame instead of on none, and takes its CPU from the confirmed
        one (docs/measurements/monitor.md)."""
        side = self.side
        yield_at = time.monotonic_ns() + YIELD_AFTER_NS if self.provisional is not None else None
        backlog = "ft_frames_backlog" if self.driver == "ft" else "joint_frames_backlog"
        while pending:
            arrived, t, frame = pending[0]
            newest = side.newest() if side is not None and self._side not in self.lost else None
            if newest is not None and newest < t and now - arrived < self.wait_s:
                break
            pending.popleft()
            lag = time.monotonic_ns() - frame.t_host_ns
            self._lags.append(lag)
            self.lag_ns = lag
            if lag > BACKLOG_NS:  # we fell behind our own reader
                self.counters[backlog] += 1
            try:
                self.handle(frame, t)
            except Exception as exc:  # noqa: BLE001 - a bad frame must not kill the monitor
                self.counters["errors"] += 1
                self.counters[f"error:{type(exc).__name__}"] += 1
            if yield_at is not None and self.backlog() and time.monotonic_ns() >= yield_at:
                return

    # -- lost streams (the worker's thread; the side stream's callback only notes the time) --------------
    def _received(self, stream: str, t_frame: int) -> None:
        self._rx_ns[stream] = time.monotonic_ns()
        if stream in self.lost and stream == self._driving:
            self._back(stream, t_frame)  # back from this sample's time: every later sample is after it

    def _check_streams(self) -> None:
        now = time.monotonic_ns()
        for stream, after in self.lost_after_ns.items():
            rx = self._rx_ns[stream]
            if rx is None:
                continue
            if stream not in self.lost and now - rx > after:
                self._lose(stream, now, rx)
            elif stream == self._side and stream in self.lost and now - rx <= after:
                back = self._side_back_t if self._side_back_t is not None else rx
                self._side_back_t = None
                self._back(stream, min(back, now))

    def _lose(self, stream: str, now: int, rx: int) -> None:
        self.lost.add(stream)
        self.losses.append([stream, now, None])
        self.counters[f"{stream}_lost"] += 1
        what = "F/T" if stream == "sensor" else "joint"
        self._stream_event(now, stream, f"{stream}_lost", f"no {what} frame for {(now - rx) / 1e9:.3f} s: "
                           + self._loss_consequence(stream))

    def _loss_consequence(self, stream: str) -> str:
        if stream == self._driving:
            return "no contact can be judged"
        if stream == "arm":
            return "blind: F/T frames are dropped unjudged until joint state returns"
        return "contacts are judged from the joints alone until it returns (the F/T sensor's links blind)"
    def _back(self, stream: str, t_ns: int) -> None:
        """The stream is back from host time t_ns (its first sample's; never before the loss)."""
        self.lost.discard(stream)
        gone = 0.0
        for loss in reversed(self.losses):
            if loss[0] == stream and loss[2] is None:
                t_ns = loss[2] = max(t_ns, loss[1])
                gone = (t_ns - loss[1]) / 1e9
                break
        self._stream_event(t_ns, stream, f"{stream}_back", f"frames again after {gone:.3f} s lost")

    def _stream_event(self, t_ns: int, stream: str, kind: str, message: str) -> None:
        counters = {k: v for k, v in self.counters.items() if isinstance(v, int)}
        ev = DeviceEvent.make(t_ns, self._source[stream], kind, message, counters)
        self.bus.publish(EVENTS_DEVICE, ev)  # first: a recording holds it before the offset it causes
        self.apply_stream_event(ev)

    def apply_stream_event(self, ev: DeviceEvent) -> None:
        """What a lost or returned stream does to the pipeline, live or replayed from a recording: a
        loss closes the open contact (an offset flagged ``lost``, at the loss's time); the joint
        stream's return restarts the acceleration estimate."""
        if ev.kind in ("sensor_lost", "arm_lost") and self.provisional is not None:
            self.provisional.reset()
        if ev.kind in ("sensor_lost", "arm_lost") and self.pipeline.in_contact:
            self.counters["contacts_lost"] += 1
            event = self.pipeline.close_contact(ev.t_host_ns, lost=True)
            for e in (self.limits.judge([event]) if self.limits is not None else [event]):
                self.counters[f"event_{e.kind}"] += 1
                self.bus.publish(EVENTS_CONTACT, e)
        elif ev.kind == "arm_back":
            self.pipeline.restart_motion()

    @staticmethod
    def _aligned(clock: ClockAligner, frame) -> int:
        if frame.t_device_ns is None:
            return frame.t_host_ns
        clock.update(frame.t_device_ns, frame.t_host_ns)
        return clock.to_host(frame.t_device_ns)

    def on_joints(self, frame) -> None:
        """A JointFrame (F/T-driven): kept with its aligned time for interpolation at the F/T samples."""
        self._rx_ns["arm"] = time.monotonic_ns()  # the worker's check sees it back
        t = self._aligned(self._arm_clock, frame)
        if "arm" in self.lost and self._side_back_t is None:
            self._side_back_t = t  # back from this sample's time: F/T frames after it are judged with it
        if self.joints.add(t, np.concatenate([frame.q, frame.qd, frame.current])) and self.provisional is not None:
            self.provisional.spread.observe(t, frame.qd)  # out of order: dropped (above), not observed

    def on_wrench(self, frame) -> None:
        """A WrenchFrame (joint-driven): kept with its aligned time for interpolation at the joint samples."""
        self._rx_ns["sensor"] = time.monotonic_ns()
        t = self._aligned(self._ft_clock, frame)
        if "sensor" in self.lost and self._side_back_t is None:
            self._side_back_t = t
        saturated = 1.0 if frame.flags & WrenchFlag.SATURATED else 0.0
        self.wrenches.add(t, np.append(frame.wrench, saturated))

    # -- the provisional onset (the worker's thread) ---------------------------------------------------------
    def _judge_provisional(self, frame, t: int) -> None:
        """One F/T frame judged at once on the joint state extrapolated to its time (at most ``wait_s`` past the
        newest joint sample); its provisional onset goes out on ``events/device`` before anything else."""
        ready = self.tared and "arm" not in self.lost and self.provisional.spread.ready
        newest = self.joints.newest_two() if ready else None
        if newest is None or t < newest[1][0] or t - newest[0][0] > self.wait_s * 1e9:
            self.counters["provisional_skipped"] += 1  # not yet ready, no joint state to extrapolate, too far past it
            return
        n = self.scene.n_joints
        (t0, x0), (t1, x1) = newest
        try:
            det, _ = self.provisional.judge(t, frame.wrench, (t0, x0[:n], x0[n:2 * n]), (t1, x1[:n], x1[n:2 * n]))
        except Exception as exc:  # noqa: BLE001 - a bad frame must not kill the monitor
            self.counters["provisional_errors"] += 1
            self.counters[f"provisional_error:{type(exc).__name__}"] += 1
            return
        self.counters["provisional_frames"] += 1
        if det.change != "onset":
            return
        onset = det.onset_t_ns if det.onset_t_ns is not None else t
        self.counters["provisional_onsets"] += 1
        self._monitor_event(onset, "provisional_onset",
                            f"judged at once on the joint state {(t - t0) / 1e6:.2f} ms past the newest joint "
                            f"sample (d2 {det.d2:.1f}); the confirmed judgement follows",
                            {"d2": det.d2, "ahead_ms": (t - t0) / 1e6, "frame_t_host_ns": t,
                             "frame_received_ns": frame.t_host_ns})
        if self.ledger.provisional(onset):
            self.counters["provisional_confirmed"] += 1

    def _settle_provisional(self, t: int, result: FrameResult) -> None:
        """The confirmed judgement of the frame at ``t``: the provisional onsets it confirms or leaves unconfirmed."""
        confirmed, unconfirmed = self.ledger.judged(t, result.detection.active)
        self.counters["provisional_confirmed"] += confirmed
        for onset in unconfirmed:
            self.counters["provisional_unconfirmed"] += 1
            self._monitor_event(onset, "provisional_unconfirmed",
                                f"the provisional onset was not confirmed: no contact judged on the interpolated "
                                f"joint state within {self.ledger.window_ns / 1e6:.0f} ms of it",
                                {"window_ms": self.ledger.window_ns / 1e6})
        if result.detection.change == "onset" and self.counters["provisional_frames"]:
            onset = result.detection.onset_t_ns if result.detection.onset_t_ns is not None else t
            if not self.ledger.had_provisional(onset):
                self.counters["onsets_without_provisional"] += 1

    def _monitor_event(self, t_ns: int, kind: str, message: str, figures: dict[str, float]) -> None:
        self.bus.publish(EVENTS_DEVICE, DeviceEvent.make(t_ns, self._source["sensor"], kind, message, figures))

    def _gap(self, span_ns: int) -> int:
        """``span_ns`` when it is more than 1.5 joint periods (missed samples), else 0."""
        period = self.joints.period_ns
        return span_ns if period is not None and 2 * span_ns > 3 * period else 0

    def handle(self, frame, t: int | None = None) -> MonitoredFrame | None:
        """Process one driving frame (a WrenchFrame, or joint-driven a JointFrame); ``t``: its aligned
        time when already computed."""
        if self.driver == "joints":
            return self._handle_joints(frame, t)
        if t is None:
            t = self._aligned(self._ft_clock, frame)
        joints = self.joints.at(t)
        if isinstance(joints, str) or "arm" in self.lost:
            if "arm" in self.lost:
                self.counters["blind_frames"] += 1
            elif joints == "before":  # the joint stream has not begun: not a loss
                self.counters["before_joint_state"] += 1
            else:
                self.counters["no_joint_state"] += 1
                self.counters[f"no_joint_state_{joints}"] += 1
            return None
        x, span = joints
        gap = self._gap(span)
        if gap:
            self.counters["joint_gap_frames"] += 1
        n = self.scene.n_joints
        inp = PipelineInput(t, frame.t_device_ns, frame.seq, frame.source, frame.wrench, x[:n], x[n:2 * n],
                            x[2 * n:], bool(frame.flags & WrenchFlag.SATURATED), tare=not self.tared,
                            joint_gap_ns=gap)
        if self.publish_inputs:
            self.bus.publish(MONITOR_INPUT, inp)
        return self.consume(inp)

    def _handle_joints(self, frame, t: int | None) -> MonitoredFrame | None:
        """One JointFrame (joint-driven), with the F/T reading at its time where one is used."""
        if t is None:
            t = self._aligned(self._arm_clock, frame)
        gap = self._joint_gap(t, frame)
        wrench, saturated = np.zeros(0), False
        if self.uses_ft and "sensor" not in self.lost:
            sampled = self.wrenches.at(t)
            if isinstance(sampled, str):  # no F/T reading at this time: judged from the joints alone
                self.counters[f"no_ft_state_{sampled}"] += 1
            else:
                wrench, saturated = sampled[0][:6], bool(sampled[0][6] > 0.0)
        elif self.uses_ft:
            self.counters["frames_without_ft"] += 1
        if gap:
            self.counters["joint_gap_frames"] += 1
        tau_j = frame.tau if self.sensing.joint_torques else None
        if self.sensing.joint_torques and tau_j is None:
            self.counters["no_joint_torques"] += 1
            return None
        inp = PipelineInput(t, frame.t_device_ns, frame.seq, frame.source, wrench, frame.q, frame.qd, frame.current,
                            saturated, tare=not self.tared, joint_gap_ns=gap, tau_j=tau_j)
        if self.publish_inputs:
            self.bus.publish(MONITOR_INPUT, inp)
        return self.consume(inp)

    def _joint_gap(self, t: int, frame) -> int:
        """Joint-driven: the span since the previous joint sample when samples were missed, else 0
        (the joint history keeps the stream's period, as it does F/T-driven)."""
        last, self._last_driving_t = self._last_driving_t, t
        self.joints.add(t, np.concatenate([frame.q, frame.qd, frame.current]))
        return 0 if last is None or t <= last else self._gap(t - last)

    def consume(self, inp: PipelineInput) -> MonitoredFrame | None:
        """One pipeline input (live, or from a recording): the tare or the pipeline; events go on the bus."""
        if inp.tare:
            self._tare(inp.t_host_ns, inp.wrench, inp.q, inp.tau_j)
            return None
        try:
            result = self._process(inp)
            if self.limits is not None:
                self.limits.observe(inp.t_host_ns, inp.q, inp.qd)
                if result.events:
                    result = replace(result, events=tuple(self.limits.judge(result.events)))
        except Exception as exc:  # noqa: BLE001 - a bad frame must not kill the monitor (nor a replay)
            self.counters["errors"] += 1
            self.counters[f"error:{type(exc).__name__}"] += 1
            return None
        self.counters["frames"] += 1
        if self.ledger is not None and self.ledger.waiting + self.counters["provisional_frames"]:
            self._settle_provisional(inp.t_host_ns, result)
        if self.publish_judged:  # before its events: a subscriber has the frame's wrench when they come
            det = result.detection
            self.bus.publish(MONITOR_JUDGED, JudgedFrame(inp.t_host_ns, inp.t_device_ns, inp.seq, inp.source,
                                                         result.external, float(det.d2), bool(det.active)))
        for event in result.events:
            self.counters[f"event_{event.kind}"] += 1
            self.bus.publish(EVENTS_CONTACT, event)
        mf = MonitoredFrame(inp.t_host_ns, inp.t_device_ns, result)
        self.latest = mf
        if self.keep_frames:
            self.frames.append(mf)
        return mf

    def _process(self, inp: PipelineInput) -> FrameResult:
        if self.driver == "ft":
            return self.pipeline.process(inp.t_host_ns, inp.wrench, inp.q, inp.qd, inp.current,
                                         saturated=inp.saturated, t_device_ns=inp.t_device_ns,
                                         joint_gap_ns=inp.joint_gap_ns)
        sensing = self.sensing
        return self.pipeline.process_joints(inp.t_host_ns, inp.q, inp.qd,
                                            current=inp.current if sensing.currents else None,
                                            tau_j=inp.tau_j if sensing.joint_torques else None,
                                            wrench=inp.wrench if inp.wrench.size else None,
                                            t_device_ns=inp.t_device_ns, joint_gap_ns=inp.joint_gap_ns)

    def _tare(self, t: int, wrench, q, tau_j=None) -> None:
        """At rest: the F/T readings' mean (the samples that had one) and the joint torque sensors'."""
        if self._tare_until_ns is None:
            self._tare_until_ns = t + int(self.tare_s * 1e9)
        self._tare_buf.append((np.asarray(wrench), np.asarray(q), None if tau_j is None else np.asarray(tau_j)))
        if t >= self._tare_until_ns:
            wrenches = [b[0] for b in self._tare_buf if b[0].size]
            torques = [b[2] for b in self._tare_buf if b[2] is not None]
            w = np.mean(wrenches, axis=0) if wrenches else None
            q = np.mean([b[1] for b in self._tare_buf], axis=0)
            tj = np.mean(torques, axis=0) if torques else None
            if self.driver == "ft":
                self.pipeline.tare(w, q, len(self._tare_buf), t)
            else:
                self.pipeline.tare(w, q, len(wrenches) or len(torques), t, tau_j=tj)
            self.tared = True
            self._tare_buf.clear()

