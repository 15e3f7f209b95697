"""The monitor's reflexes: every contact onset stops the arm (``ftc monitor --reflex stop``), or moves the
touched point back along the contact's force (``--reflex retreat``), unless the contact is guided."""
from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from ftc_hw.bus import EVENTS_CONTACT, EVENTS_DEVICE, Bus, ContactEvent, DeviceEvent, StaleDataError
from ftc_hw.model import ArmModel
from ftc_hw.pipeline.provisional import CONFIRM_WINDOW_NS

from .config import RetreatSettings
from .retreat import RetreatError, RetreatPath, plan_retreat, retreat_direction
from .retreat_region import SurfaceSamples

HANDOVER_WAIT_S = 0.002  # the longest an onset's publisher waits for the stop reflex's thread to take it


class StopReflex:
    """On every contact onset, ``stop(onset)``: the local arm adapter's ``stop()`` from a thread of its own
    (it waits for the device: never in the pipeline's thread), or, ``inline``, a command to the arm's
    reader process (:meth:`~ftc_hw.app.serving.remote_rig.RemoteRig.stop_arm`: a Zenoh put that does not wait)
    at once in the thread that published the onset (a hand-over cost 0.2-0.3 ms, ftc bench reflex).
    It gets the onset before any other subscriber of the monitor's bus.

    The onset it acts on is the first of a contact's provisional onset (a ``provisional_onset`` device event:
    judged at once on the extrapolated joint state) and its confirmed one (a ContactEvent): the other, within
    ``CONFIRM_WINDOW_NS`` of it, stops nothing again (counted in ``followed``). ``stops`` say which it was."""

    def __init__(self, bus: Bus, stop: Callable[[ContactEvent], None], inline: bool = False) -> None:
        self.stop, self.inline = stop, inline
        self.followed = 0  # onsets within the window of one acted on (a provisional one's confirmation)
        self._acted_ns: int | None = None  # the onset time of the last one acted on
        self.stops: list[dict[str, Any]] = []
        self.errors: list[str] = []
        self._pending: list[tuple[ContactEvent, int]] = []  # with when each was published
        self._wake = threading.Event()
        self._taken = threading.Event()
        self._quit = False
        # first: the onset must not wait for the event's recording or its forwarding to Zenoh
        self._sub = bus.subscribe(EVENTS_CONTACT, callback=self._on_event, first=True)
        self._device_sub = bus.subscribe(EVENTS_DEVICE, callback=self._on_event, first=True)
        self._thread = threading.Thread(target=self._run, name="stop-reflex", daemon=True)
        self._thread.start()

    def _on_event(self, ev: ContactEvent | DeviceEvent) -> None:
        if ev.kind not in ("onset", "provisional_onset"):
            return
        if self._acted_ns is not None and abs(ev.t_host_ns - self._acted_ns) <= CONFIRM_WINDOW_NS:
            self.followed += 1
            return
        self._acted_ns = ev.t_host_ns
        if isinstance(ev, DeviceEvent):  # the stop command carries an onset: the provisional one, where unknown
            ev = ContactEvent.make(ev.t_host_ns, "onset", "provisional", np.zeros(3), np.zeros(3),
                                   flags=("provisional",))
        if self.inline:
            self._send(ev, time.monotonic_ns())
        else:
            self._taken.clear()
            self._pending.append((ev, time.monotonic_ns()))
            self._wake.set()
            # the publisher waits (the interpreter released) until the reflex's thread has the onset: going on, it
            # would keep the interpreter up to a switch interval, and other threads may come first (measured: ~1 ms
            # from the onset's publication to the stop's sending, median, at 1 kHz on a busy 2-core host)
            self._taken.wait(HANDOVER_WAIT_S)

    def _send(self, ev: ContactEvent, t_seen: int) -> None:
        """``t_seen``: when the onset was published (the hand-over to this thread is the time from then)."""
        t0 = time.monotonic_ns()
        try:
            self.stop(ev)
            self.stops.append({"onset_t_host_ns": ev.t_host_ns, "sent_after_onset_ms": (t0 - ev.t_host_ns) / 1e6,
                               "seen_after_onset_ms": (t_seen - ev.t_host_ns) / 1e6,
                               "stop_call_ms": (time.monotonic_ns() - t0) / 1e6,
                               "provisional": "provisional" in ev.flags})
        except Exception as exc:  # noqa: BLE001 - reported, the monitor goes on
            self.errors.append(f"{type(exc).__name__}: {exc}")

    def _run(self) -> None:
        while not self._quit:
            self._wake.wait(0.5)
            self._wake.clear()
            while self._pending:
                ev, t_seen = self._pending.pop(0)
                self._taken.set()
                self._send(ev, t_seen)

    def close(self) -> None:
        self._sub.close()
        self._device_sub.close()
        self._quit = True
        self._wake.set()
        self._thread.join(5.0)


def guidance_of(ev: Any) -> float | None:
    """The event's probability that a person is guiding the arm (``p_guidance``, docs/contacts.md), or None
    when nothing classified the contact (``intent`` empty: an event from before the classifier)."""
    if not getattr(ev, "intent", ""):
        return None
    return float(ev.p_guidance)


def intent_known(ev: Any) -> bool:
    """The classifier has named the contact's intent (guidance or impact), or nothing classifies it, or it
    has ended: the reflex need not wait for a later event of it."""
    return getattr(ev, "intent", "") != "unknown" or getattr(ev, "kind", "") == "offset"


def kind_trigger(kind: str) -> Callable[[Any], bool]:
    """A trigger on contact events of one kind (``onset``, the default; ``exceedance``: a limit crossed)."""
    return lambda ev: isinstance(ev, ContactEvent) and ev.kind == kind


class RetreatReflex:
    """``--reflex retreat``: on a trigger (every contact event of ``settings.trigger``'s kind: an onset, or an
    exceedance of the body limits; ``triggers`` any other predicate; ``trigger(event)`` retreats at once), unless
    :meth:`should_retreat` says the contact is guided, the touched point -- every point of the arm it may be at
    (:class:`~ftc_hw.app.monitor.retreat_region.SurfaceSamples`) -- is moved back along the contact normal by
    ``settings.distance_m`` within ``settings.time_limit_s``: first a setpoint where the arm is (it brakes
    meanwhile), then a joint path planned from the arm's newest joint state
    (:func:`~ftc_hw.app.monitor.retreat.retreat_direction`, :func:`~ftc_hw.app.monitor.retreat.plan_retreat`;
    a plan that fails ends the stream there: a stop; one that falls short, a ``retreat_short`` event), streamed
    to the arm's adapter (``servo``: DYNAMIXEL Goal Position, a UR's RTDE registers) one setpoint every
    ``arm.servo_period_s``, from a thread of its own (never the pipeline's). One retreat at a time: a trigger
    during one is counted (``ignored``), not queued. ``retreats`` holds each one's figures."""

    def __init__(self, bus: Bus, arm: Any, model: ArmModel, settings: RetreatSettings, *, joints_topic: str,
                 triggers: Callable[[Any], bool] | None = None,
                 guidance: Callable[[Any], float | None] = guidance_of,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        self.bus, self.arm, self.model, self.settings, self._sleep = bus, arm, model, settings, sleep
        self.joints_topic, self.guidance = joints_topic, guidance
        self.triggers = triggers or kind_trigger(settings.trigger)
        self.retreats: list[dict[str, Any]] = []
        self.not_fought: list[dict[str, Any]] = []  # guided contacts left alone
        self.errors: list[str] = []
        self.ignored = 0
        self._pending: ContactEvent | None = None
        self._force_sum: dict[int, np.ndarray] = {}  # per contact id: its estimates' forces added (N)
        self._planned: set[int] = set()  # contact ids whose retreat is planned (their later estimates unused)
        self._newest: dict[int, ContactEvent] = {}  # per recent contact id: its newest event (its class so far)
        # per recent contact id: its newest event names the intent the one before it named (or closes it)
        self._settled: dict[int, bool] = {}
        self._news = threading.Event()  # a contact event came (a held retreat's decision may be due)
        self._busy = False
        self._wake = threading.Event()
        self._quit = threading.Event()
        self._samples = SurfaceSamples(model)  # where on the arm a contact may be (a few 0.1 s, once)
        arm.prepare_servo()
        self._sub = bus.subscribe(EVENTS_CONTACT, callback=self._on_event, first=True)
        self._thread = threading.Thread(target=self._run, name="retreat-reflex", daemon=True)
        self._thread.start()

    def _on_event(self, ev: Any) -> None:
        if isinstance(ev, ContactEvent):
            prior = self._newest.get(ev.contact_id)
            self._settled[ev.contact_id] = ev.kind == "offset" or (
                intent_known(ev) and prior is not None and getattr(prior, "intent", "") == getattr(ev, "intent", ""))
            self._newest[ev.contact_id] = ev
            if len(self._newest) > 64:
                self._settled.pop(next(iter(self._newest)), None)
                self._newest.pop(next(iter(self._newest)))
            self._news.set()
        if isinstance(ev, ContactEvent) and ev.kind != "offset" and ev.contact_id not in self._planned:
            # the contact's force estimates until the retreat begins (an update's may be better than the
            # onset's first frame; during the retreat the arm's own acceleration disturbs them)
            total = self._force_sum.get(ev.contact_id) if ev.kind != "onset" else None
            self._force_sum[ev.contact_id] = ev.force if total is None else total + ev.force
        if self.triggers(ev):
            self.trigger(ev)

    def should_retreat(self, ev: Any) -> bool:
        """False for a contact classified as guidance (its probability above ``settings.guided_above``)."""
        g = self.guidance(ev)
        return g is None or g <= self.settings.guided_above

    def trigger(self, ev: ContactEvent) -> None:
        """Retreat from the contact ``ev`` (its link, point and force) now, unless it is guided or a retreat
        is under way. Returns at once; the motion runs on the reflex's thread."""
        if not self.should_retreat(ev):
            self.not_fought.append({"onset_t_host_ns": ev.t_host_ns, "contact_id": ev.contact_id,
                                    "guidance": self.guidance(ev)})
            return
        if self._busy or self._pending is not None:
            self.ignored += 1
            return
        self._pending = ev
        self._wake.set()

    def _run(self) -> None:
        while not self._quit.is_set():
            self._wake.wait(0.5)
            self._wake.clear()
            ev = self._pending
            if ev is None:
                continue
            self._busy = True  # before the pending one is taken: idle() never sees neither
            self._pending = None
            try:
                done = self._retreat(ev)
                if done is not None:
                    self.retreats.append(done)
            except Exception as exc:  # noqa: BLE001 - reported, the monitor goes on
                self.errors.append(f"{type(exc).__name__}: {exc}")
            finally:
                self._busy = False

    def _retreat(self, ev: ContactEvent) -> dict[str, Any] | None:
        """One retreat's figures, or None for a contact that turned out guided while the arm was held."""
        t0 = time.monotonic_ns()
        frame = self.bus.latest(self.joints_topic)
        if frame is None:
            raise RetreatError(f"no joint state on {self.joints_topic}")
        # first a setpoint where the arm is: it brakes while the retreat is decided and planned (milliseconds,
        # more on a loaded host), as the stop reflex would; a still arm whose contact's intent is not known yet
        # is left free until it is (a hand may be leading it: held, it would fight the hand)
        speed, into = self._point_motion(frame, ev)
        held = intent_known(ev) or speed > self.settings.moving_above_m_s or into > self.settings.pushing_above_m_s
        if held:
            self.arm.servo(frame.q)
        t_first = time.monotonic_ns()
        decided = self._decide(ev, early=held)
        if not self.should_retreat(decided):  # a hand guides it: let go (or leave it), the arm follows the hand
            if held:
                self.arm.end_servo()
            self.not_fought.append({"onset_t_host_ns": ev.t_host_ns, "contact_id": ev.contact_id,
                                    "guidance": self.guidance(decided), "held": held,
                                    "waited_ms": (time.monotonic_ns() - t0) / 1e6})
            return None
        if not held:  # decided an accident: the arm is held from where it is now
            frame = self.bus.latest(self.joints_topic) or frame
            self.arm.servo(frame.q)
            t_first = time.monotonic_ns()
        # the path starts at the setpoint that holds the arm, not where the arm is now: braking, it goes on past
        # that setpoint and comes back to it meanwhile, and a path from a measured position it has already
        # left behind would first send it forward again, into what it touched (seen on a loaded host: 70 ms
        # from the hold to the path, the contact made again)
        t_decided = time.monotonic_ns()
        try:
            direction, why, path = self._plan(ev, frame, decided if decided.kind != "offset" else ev)
        except Exception:
            self.arm.end_servo()  # no retreat: the arm stays where the first setpoint held it (a stop)
            raise
        t_planned = time.monotonic_ns()
        short = self._say_short(ev, path)
        sent = 1 + self._stream(path)
        return {"onset_t_host_ns": ev.t_host_ns, "contact_id": ev.contact_id, "link": ev.link,
                "decided_on": decided.kind, "intent": getattr(decided, "intent", ""),
                "decide_ms": (t_decided - t_first) / 1e6, "decided_after_onset_ms": (t_decided - ev.t_host_ns) / 1e6,
                "plan_ms": (t_planned - t0) / 1e6, "planning_ms": (t_planned - t_decided) / 1e6,
                "first_setpoint_after_onset_ms": (t_first - ev.t_host_ns) / 1e6,
                "setpoints": sent, "duration_s": path.duration_s, "moved_m": path.moved_m, "least_m": path.least_m,
                "region_points": path.points, "needed_s": path.needed_s, "time_cut": path.time_cut,
                "direction": path.direction.tolist(), "direction_from": why, "clipped": path.clipped,
                "within_time_limit": path.within(self.settings.time_limit_s), "short": short}

    def _point_motion(self, frame: Any, ev: ContactEvent) -> tuple[float, float]:
        """The touched point's speed (m/s) at ``frame``'s joints, and its speed into the contact (against the
        estimated force on the arm: positive when the arm pushes on what it touches); 0 where unknown."""
        try:
            jac = self.model.jacobian(np.asarray(frame.q, dtype=float), ev.link, np.asarray(ev.point, dtype=float))
            v = jac @ np.asarray(frame.qd, dtype=float)
        except (KeyError, ValueError):
            return 0.0, 0.0
        f = np.asarray(ev.force, dtype=float)
        norm = float(np.linalg.norm(f))
        into = float(-(v @ f) / norm) if norm > 1e-9 else 0.0
        speed = float(np.linalg.norm(v))
        return (speed if math.isfinite(speed) else 0.0), (into if math.isfinite(into) else 0.0)

    def _say_short(self, ev: ContactEvent, path: RetreatPath) -> str:
        """A retreat that moves some point the contact may be at less than the distance (cut to the time
        limit, the path's length cap, a joint range) is said on the bus (a ``retreat_short`` device event)
        before it starts; the message, or "" when every point goes back the distance."""
        distance = self.settings.distance_m
        if path.least_m >= distance - 5e-4 and not path.time_cut:
            return ""
        why = (f"it would take {path.needed_s:.3f} s, cut to the {self.settings.time_limit_s:g} s limit"
               if path.time_cut else "a joint range" if path.clipped else
               f"the path's length cap (max_scale {self.settings.max_scale:g})")
        msg = (f"retreat from contact {ev.contact_id} on {ev.link}: {why}; the estimated point goes back "
               f"{path.moved_m * 1e3:.1f} mm, every point it may be at ({path.points}) at least "
               f"{path.least_m * 1e3:.1f} mm of {distance * 1e3:.1f}")
        self.bus.publish(EVENTS_DEVICE, DeviceEvent.make(
            time.monotonic_ns(), "retreat", "retreat_short", msg,
            {"contact_id": ev.contact_id, "distance_m": distance, "moved_m": path.moved_m, "least_m": path.least_m,
             "duration_s": path.duration_s, "needed_s": path.needed_s, "time_cut": float(path.time_cut)}))
        return msg

    def _decide(self, ev: ContactEvent, *, early: bool = True) -> ContactEvent:
        """``ev`` when it names the contact's intent (an arm moving into it: an impact at once), else the contact's
        newest event at ``decide_s`` after its onset sample, or once it has closed, or (``early``: a held arm) once
        two events in a row name the same intent. A still arm is not decided early: the classifier cannot tell a
        hand from a clamp until the arm has had time to yield to it (live, a hand-guided arm yielded at 0.015 m/s
        for its first 0.4 s and the classifier named it an impact for three updates, then guidance at 0.44 s),
        and the arm left free meanwhile pushes on nothing; on a held arm the guidance probability can cross a
        bound for one update as a hand's force builds (seen at 0.32 s: "impact" between "unknown"s)."""
        if intent_known(ev):
            return ev
        deadline = ev.t_host_ns + int(self.settings.decide_s * 1e9)
        cid = ev.contact_id
        while not self._quit.is_set():
            self._news.clear()  # before the look: an event that comes after it sets it again
            newest = self._newest.get(cid, ev)
            if newest.kind == "offset" or (early and self._settled.get(cid, False)):
                break
            remaining = (deadline - time.monotonic_ns()) / 1e9
            if remaining <= 0:
                break
            self._news.wait(remaining)
        return self._newest.get(cid, ev)

    def _plan(self, ev: ContactEvent, frame: Any, at: ContactEvent) -> tuple[np.ndarray, str, RetreatPath]:
        """The direction, why that one, and the path, from the setpoint holding the arm (``frame``) and the
        joints at the onset ``ev``; the contact where its newest estimate ``at`` (the onset, or an update) puts it."""
        try:  # where the arm was at the onset: the point moves back from there
            touch = self.bus.sample_at(self.joints_topic, ev.t_host_ns)
        except StaleDataError:
            touch = frame
        force = self._force_sum.get(ev.contact_id, ev.force)  # the estimates so far: their sum's direction
        self._planned.add(ev.contact_id)
        direction, why = retreat_direction(self.model, touch.q, touch.qd, link=at.link, point=at.point, force=force,
                                           settings=self.settings)
        s = self.settings
        region = self._samples.region(touch.q, link=at.link, point=at.point, point_std=at.point_std,
                                      floor_m=s.region_floor_m, reach_m=s.region_reach_m, force=at.force,
                                      tube_m=s.region_tube_m)
        path = plan_retreat(self.model, frame.q, link=at.link, point=at.point, direction=direction, settings=s,
                            period_s=self.arm.servo_period_s, q_touch=touch.q, region=region,
                            qd_touch=touch.qd if why == "motion" else None)  # ran into it: every point retraces
        return direction, why, path

    def _stream(self, path: RetreatPath) -> int:
        """Every setpoint after the first (the arm's own position) at its time; how many were sent."""
        start = time.monotonic()
        sent = 0
        for t, q in zip(path.t[1:], path.q[1:], strict=True):
            if self._quit.is_set():
                break
            delay = start + t - path.t[1] - time.monotonic()
            if delay > 0:
                self._sleep(delay)
            self.arm.servo(q)
            sent += 1
        self.arm.end_servo()
        return sent

    def idle(self) -> bool:
        """No retreat pending or under way."""
        return self._pending is None and not self._busy

    def close(self) -> None:
        self._sub.close()
        self._quit.set()
        self._wake.set()
        self._thread.join(5.0)
