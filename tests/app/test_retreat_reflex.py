"""The retreat reflex (``ftc monitor --reflex retreat``) on a bus with a recording arm, no devices: an onset
streams the planned setpoints to the arm (the first where the arm is: it brakes while the retreat is
planned), ends the stream; a contact classified as guidance is not fought; another trigger (a limit's
exceedance, later) comes in through ``trigger``; a failure is reported, not raised. The motion's time is
not waited for (``sleep`` does nothing): what is checked is what is sent."""
from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest

from ftc_hw.app.monitor.config import RetreatSettings
from ftc_hw.app.monitor.reflex import RetreatReflex
from ftc_hw.app.monitor.retreat import point_at
from ftc_hw.bus import EVENTS_CONTACT, EVENTS_DEVICE, Bus, ContactEvent, JointFrame, joints_topic
from ftc_hw.model import ArmModel
from ftc_hw.scene import load_scene

pytestmark = pytest.mark.compute

SCENE = load_scene("ur5e")
MODEL = ArmModel(SCENE)
TOPIC = joints_topic("arm")
Q0 = np.array(SCENE.robot.home)


class RecordingArm:
    servo_period_s = 0.002

    def __init__(self) -> None:
        self.prepared = False
        self.setpoints: list[np.ndarray] = []
        self.ended = 0

    def prepare_servo(self) -> None:
        self.prepared = True

    def servo(self, q) -> None:
        self.setpoints.append(np.array(q, dtype=float))

    def end_servo(self) -> None:
        self.ended += 1


@pytest.fixture
def rig():
    bus, arm = Bus(), RecordingArm()
    t = time.monotonic_ns()
    for k in range(5):
        bus.publish(TOPIC, JointFrame.make(t - (5 - k) * 2_000_000, Q0, np.zeros(6), np.zeros(6), None,
                                           source="arm", seq=k))
    reflex = RetreatReflex(bus, arm, MODEL, RetreatSettings(distance_m=0.03), joints_topic=TOPIC,
                           sleep=lambda s: None)
    yield bus, arm, reflex
    reflex.close()


def _onset(contact_id: int = 1, guidance: float | None = None, force=(0.0, 0.0, 25.0)) -> ContactEvent:
    point = MODEL.kinematics(Q0)["wrist_3"][:3, 3]
    base = ContactEvent.make(time.monotonic_ns() - 1_000_000, "onset", "wrist_3", point, force,
                             contact_id=contact_id)
    if guidance is None:
        return base
    # as the classifier gives it (ftc_hw/pipeline/classify.py): the intent and its probability
    return dataclasses.replace(base, intent="guidance" if guidance > 0.5 else "impact", p_guidance=guidance)


def _settle(reflex: RetreatReflex) -> None:
    end = time.monotonic() + 10.0
    while not reflex.idle() and time.monotonic() < end:
        time.sleep(0.01)
    assert reflex.idle()


def test_an_onset_streams_the_retreat_to_the_arm(rig):
    bus, arm, reflex = rig
    assert arm.prepared
    ev = _onset()
    bus.publish(EVENTS_CONTACT, ev)
    _settle(reflex)
    assert not reflex.errors, reflex.errors
    (r,) = reflex.retreats
    assert np.allclose(arm.setpoints[0], Q0)  # first: hold where it is
    assert len(arm.setpoints) == r["setpoints"] > 10 and arm.ended == 1
    end = point_at(MODEL, Q0, arm.setpoints[-1], link="wrist_3", point=ev.point)
    # up, with the force; every point the contact may be at (its region: the estimate's 5 mm floor) at least 3 cm
    assert 0.03 - 1e-4 <= (end - ev.point) @ np.array([0.0, 0.0, 1.0]) <= 0.033
    assert r["least_m"] >= 0.03 - 1e-4 and r["region_points"] > 1
    assert r["within_time_limit"] and r["first_setpoint_after_onset_ms"] >= 1.0
    steps = np.abs(np.diff(np.array(arm.setpoints), axis=0)).max(axis=0)
    assert np.all(steps <= SCENE.robot.max_speed * arm.servo_period_s * 1.01)


def test_a_guided_contact_is_not_fought(rig):
    bus, arm, reflex = rig
    bus.publish(EVENTS_CONTACT, _onset(1, guidance=0.9))
    _settle(reflex)
    assert not arm.setpoints and not reflex.retreats
    assert reflex.not_fought == [{"onset_t_host_ns": reflex.not_fought[0]["onset_t_host_ns"], "contact_id": 1,
                                  "guidance": 0.9}]
    bus.publish(EVENTS_CONTACT, _onset(2, guidance=0.2))  # classified, but as an accident: retreat
    _settle(reflex)
    assert len(reflex.retreats) == 1 and arm.setpoints
    assert reflex.should_retreat(_onset(3)) and not reflex.should_retreat(_onset(3, guidance=0.51))


def _unknown(ev: ContactEvent, kind: str = "onset", guidance: float = 0.4, **kw) -> ContactEvent:
    """``ev`` as the classifier gives it before it knows: intent unknown (or named, where ``guidance`` says)."""
    intent = "guidance" if guidance >= 0.8 else "impact" if guidance <= 0.2 else "unknown"
    return dataclasses.replace(ev, kind=kind, intent=intent, p_guidance=guidance, **kw)


def test_an_undecided_onset_leaves_a_still_arm_free_and_a_guiding_hand_is_not_fought(rig):
    """A still arm touched: a hand may be leading it, so it is not held while the classifier decides (held, it
    would fight the hand: the guidance scenario's hands then pushed as clamps do, and were retreated from)."""
    bus, arm, reflex = rig
    onset = _unknown(_onset(5))
    bus.publish(EVENTS_CONTACT, onset)
    time.sleep(0.01)
    bus.publish(EVENTS_CONTACT, _unknown(onset, "update", 0.9, t_host_ns=onset.t_host_ns + 20_000_000))
    _settle(reflex)
    assert not reflex.retreats and arm.setpoints == [] and arm.ended == 0
    (nf,) = reflex.not_fought
    assert nf["contact_id"] == 5 and nf["guidance"] == 0.9 and not nf["held"] and nf["waited_ms"] > 5.0


def test_an_undecided_onset_on_a_moving_arm_holds_it_and_lets_go_of_a_guiding_hand(rig):
    bus, arm, reflex = rig
    _moving(bus)
    onset = _unknown(_onset(9))
    bus.publish(EVENTS_CONTACT, onset)
    time.sleep(0.01)
    bus.publish(EVENTS_CONTACT, _unknown(onset, "update", 0.9, t_host_ns=onset.t_host_ns + 20_000_000))
    _settle(reflex)
    assert not reflex.retreats and len(arm.setpoints) == 1 and np.allclose(arm.setpoints[0], Q0)
    assert arm.ended == 1  # held while undecided, then let go
    (nf,) = reflex.not_fought
    assert nf["held"] and nf["waited_ms"] > 5.0


QD_MOVING = np.array([0.3, 0.0, 0.0, 0.0, 0.0, 0.0])  # the base joint: the wrist's point at ~0.15 m/s


def _moving(bus: Bus) -> None:
    bus.publish(TOPIC, JointFrame.make(time.monotonic_ns(), Q0, QD_MOVING, np.zeros(6), None, source="arm", seq=8))


def test_an_undecided_onset_retreats_at_the_deadline_or_from_the_update_that_names_an_impact(rig):
    bus, arm, reflex = rig
    bus.publish(EVENTS_CONTACT, _unknown(_onset(6)))  # nothing more comes: decided on the onset, at decide_s
    _settle(reflex)
    (r,) = reflex.retreats
    assert r["decided_on"] == "onset" and r["intent"] == "unknown" and r["decided_after_onset_ms"] >= 600.0
    assert r["first_setpoint_after_onset_ms"] >= 600.0  # a still arm: held once decided, not before
    _moving(bus)  # a moving arm is held at once, and decided as soon as two events name the intent
    onset = _unknown(_onset(7))
    moved = onset.point + np.array([0.0, 0.0, -0.02])  # the update's estimate: 2 cm lower on the link
    bus.publish(EVENTS_CONTACT, onset)
    bus.publish(EVENTS_CONTACT, _unknown(onset, "update", 0.05))
    bus.publish(EVENTS_CONTACT, _unknown(onset, "update", 0.05, point=moved))  # two in a row name an impact
    _settle(reflex)
    r = reflex.retreats[1]
    assert r["decided_on"] == "update" and r["intent"] == "impact" and r["decide_ms"] < 50.0
    end = point_at(MODEL, Q0, arm.setpoints[-1], link="wrist_3", point=moved)
    # the update's point went back the distance, the way it came (the arm ran into it)
    assert r["direction_from"] == "motion" and (end - moved) @ np.array(r["direction"]) >= 0.03 - 1e-4


def _onset_and_updates(bus: Bus, contact_id: int, guidance: tuple[float, ...], *, gap_s: float) -> None:
    """An undecided onset, then an update per guidance probability, ``gap_s`` apart."""
    onset = _unknown(_onset(contact_id))
    bus.publish(EVENTS_CONTACT, onset)
    for p in guidance:
        time.sleep(gap_s)
        bus.publish(EVENTS_CONTACT, _unknown(onset, "update", p))


def test_one_update_that_names_an_impact_between_unknowns_does_not_decide(rig):
    """As a hand's force builds the classifier's guidance probability can dip under its bound for one update
    (seen live at 0.32 s); two in a row decide."""
    bus, arm, reflex = rig
    _moving(bus)
    _onset_and_updates(bus, 10, (0.4, 0.15, 0.45, 0.9, 0.95), gap_s=0.005)
    _settle(reflex)
    assert not reflex.retreats and len(arm.setpoints) == 1 and arm.ended == 1
    (nf,) = reflex.not_fought
    assert nf["guidance"] == 0.95 and nf["waited_ms"] < 400.0  # decided on the two that named guidance


def test_a_still_arm_is_decided_on_the_contacts_newest_event_at_the_deadline():
    """A hand-guided arm yields slowly at first: the classifier named such a contact an impact for three
    updates before it named guidance (live, 0.33-0.44 s). A still arm is left free and decided at decide_s."""
    bus, arm = Bus(), RecordingArm()
    bus.publish(TOPIC, JointFrame.make(time.monotonic_ns(), Q0, np.zeros(6), np.zeros(6), None, source="arm", seq=0))
    reflex = RetreatReflex(bus, arm, MODEL, RetreatSettings(distance_m=0.03, decide_s=0.2), joints_topic=TOPIC,
                           sleep=lambda s: None)
    try:
        _onset_and_updates(bus, 11, (0.15, 0.15, 0.15, 0.9, 0.95), gap_s=0.02)
        _settle(reflex)
        assert not reflex.retreats and arm.setpoints == []
        (nf,) = reflex.not_fought
        assert nf["guidance"] == 0.95 and not nf["held"] and nf["waited_ms"] >= 150.0
    finally:
        reflex.close()


def test_the_path_starts_at_the_hold_though_the_arm_braked_past_it_meanwhile(rig):
    """Braking, the arm goes on past the hold and comes back to it: a path that started from a joint state
    taken while undecided would send it forward first, towards what it touched."""
    bus, arm, reflex = rig
    _moving(bus)  # held at once
    onset = _unknown(_onset(8))
    bus.publish(EVENTS_CONTACT, onset)
    time.sleep(0.02)  # held by now; the arm is reported 0.02 rad on past the hold before the retreat is decided
    past = Q0 + np.array([0.02, 0.0, 0.0, 0.0, 0.0, 0.0])
    bus.publish(TOPIC, JointFrame.make(time.monotonic_ns(), past, np.zeros(6), np.zeros(6), None, source="arm", seq=9))
    bus.publish(EVENTS_CONTACT, _unknown(onset, "update", 0.05))
    _settle(reflex)
    assert not reflex.errors and len(reflex.retreats) == 1, reflex.errors
    sent = np.array(arm.setpoints)
    assert np.allclose(sent[0], Q0) and np.abs(sent[1] - Q0).max() < 0.01  # continuous from the hold
    steps = np.abs(np.diff(sent, axis=0)).max(axis=0)
    assert np.all(steps <= SCENE.robot.max_speed * arm.servo_period_s * 1.01)


def test_other_triggers_come_in_through_trigger(rig):
    """An update is no trigger by default; ``trigger(event)`` retreats from it (a limit's exceedance would)."""
    bus, arm, reflex = rig
    update = dataclasses.replace(_onset(4), kind="update")
    bus.publish(EVENTS_CONTACT, update)
    _settle(reflex)
    assert not arm.setpoints
    reflex.trigger(update)
    _settle(reflex)
    assert len(reflex.retreats) == 1 and reflex.retreats[0]["contact_id"] == 4


def test_retreat_on_exceedance_waits_for_the_limit():
    """``trigger="exceedance"``: an onset moves nothing; the contact's exceedance of its body limit does."""
    bus, arm = Bus(), RecordingArm()
    bus.publish(TOPIC, JointFrame.make(time.monotonic_ns() - 2_000_000, Q0, np.zeros(6), np.zeros(6), None,
                                       source="arm", seq=0))
    reflex = RetreatReflex(bus, arm, MODEL, RetreatSettings(trigger="exceedance"), joints_topic=TOPIC,
                           sleep=lambda s: None)
    try:
        ev = _onset(8)
        bus.publish(EVENTS_CONTACT, ev)
        _settle(reflex)
        assert not arm.setpoints
        bus.publish(EVENTS_CONTACT, dataclasses.replace(ev, kind="exceedance"))
        _settle(reflex)
        assert len(reflex.retreats) == 1 and arm.setpoints and arm.ended == 1
    finally:
        reflex.close()
    with pytest.raises(ValueError, match="trigger"):
        RetreatSettings(trigger="offset")


def test_the_direction_is_the_contacts_estimates_until_the_retreat():
    """The onset's force (up), then an update's (sideways) before the retreat is planned: the retreat goes
    along their sum. (Triggered by hand here, so that the update is in before the plan.)"""
    bus, arm = Bus(), RecordingArm()
    bus.publish(TOPIC, JointFrame.make(time.monotonic_ns() - 2_000_000, Q0, np.zeros(6), np.zeros(6), None,
                                       source="arm", seq=0))
    reflex = RetreatReflex(bus, arm, MODEL, RetreatSettings(), joints_topic=TOPIC, triggers=lambda ev: False,
                           sleep=lambda s: None)
    try:
        ev = _onset(5, force=(0.0, 0.0, 10.0))
        bus.publish(EVENTS_CONTACT, ev)
        bus.publish(EVENTS_CONTACT, dataclasses.replace(ev, kind="update", force=np.array([10.0, 0.0, 0.0])))
        assert not arm.setpoints  # no trigger of its own
        reflex.trigger(ev)
        _settle(reflex)
        assert np.allclose(reflex.retreats[0]["direction"], [2 ** -0.5, 0.0, 2 ** -0.5])
        # after the plan, the contact's later estimates (disturbed by the retreat's own motion) are not added
        bus.publish(EVENTS_CONTACT, dataclasses.replace(ev, kind="update", force=np.array([0.0, 50.0, 0.0])))
        assert np.allclose(reflex._force_sum[5], [10.0, 0.0, 10.0])
    finally:
        reflex.close()


def test_a_failed_retreat_is_reported_and_the_next_one_runs(rig):
    bus, arm, reflex = rig
    bus.publish(EVENTS_CONTACT, _onset(6, force=(0.0, 0.0, 0.0)))  # a still arm and no force: no direction
    _settle(reflex)
    assert reflex.errors and "no direction" in reflex.errors[0]
    assert len(arm.setpoints) == 1 and arm.ended == 1  # the first setpoint held it there: a stop
    bus.publish(EVENTS_CONTACT, _onset(7))
    _settle(reflex)
    assert len(reflex.retreats) == 1


def test_a_retreat_cut_to_its_time_limit_is_said():
    """20 ms cannot move the wrist 3 cm within ur5e's limits: the stream ends in 20 ms and a ``retreat_short``
    event says how far the point goes instead; a retreat in time says nothing."""
    bus, arm = Bus(), RecordingArm()
    bus.publish(TOPIC, JointFrame.make(time.monotonic_ns() - 2_000_000, Q0, np.zeros(6), np.zeros(6), None,
                                       source="arm", seq=0))
    said = bus.subscribe(EVENTS_DEVICE, maxsize=None)
    reflex = RetreatReflex(bus, arm, MODEL, RetreatSettings(time_limit_s=0.02), joints_topic=TOPIC,
                           sleep=lambda s: None)
    try:
        bus.publish(EVENTS_CONTACT, _onset(9))
        _settle(reflex)
        (r,) = reflex.retreats
        assert r["time_cut"] and r["duration_s"] == pytest.approx(0.02) and r["needed_s"] > 0.02
        assert len(arm.setpoints) == r["setpoints"] <= 0.02 / arm.servo_period_s + 2
        (ev,) = [e for e in said.drain() if e.kind == "retreat_short"]
        assert ev.counters["contact_id"] == 9 and 0.0 < ev.counters["moved_m"] < 0.03
        assert "cut to the 0.02 s limit" in ev.message and ev.message == r["short"]
    finally:
        reflex.close()
    bus, arm = Bus(), RecordingArm()
    bus.publish(TOPIC, JointFrame.make(time.monotonic_ns() - 2_000_000, Q0, np.zeros(6), np.zeros(6), None,
                                       source="arm", seq=0))
    said = bus.subscribe(EVENTS_DEVICE, maxsize=None)
    reflex = RetreatReflex(bus, arm, MODEL, RetreatSettings(), joints_topic=TOPIC, sleep=lambda s: None)
    try:
        bus.publish(EVENTS_CONTACT, _onset(10))
        _settle(reflex)
        assert not reflex.retreats[0]["short"] and not [e for e in said.drain() if e.kind == "retreat_short"]
    finally:
        reflex.close()
