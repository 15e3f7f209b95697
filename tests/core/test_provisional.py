"""The provisional onset (issue 40): each F/T frame judged at once on the joint state extrapolated past the
newest joint sample, with the extrapolation's error in the detection covariance; the confirmed judgement
follows on the interpolated state, and a provisional onset it does not confirm is an event of its own."""
from __future__ import annotations

from collections import deque

import numpy as np
import pytest

from ftc_hw.bus import EVENTS_CONTACT, EVENTS_DEVICE, Bus, JointFrame, WrenchFrame
from ftc_hw.compensation.extrapolation import (
    AccelerationSpread,
    extrapolate,
    extrapolation_rows,
    wrench_sensitivities,
)
from ftc_hw.detection.kernels import quad_sum
from ftc_hw.model import ArmModel
from ftc_hw.monitor import LiveMonitor
from ftc_hw.pipeline.provisional import ProvisionalLedger
from ftc_hw.scene import load_scene
from tests.conftest import settings

SCENE = load_scene("ur5e")
HOME = np.asarray(SCENE.robot.home, dtype=float)
MS = 1_000_000


def test_extrapolation_is_exact_at_constant_acceleration():
    a, v0 = np.linspace(-2.0, 2.0, 6), np.linspace(0.5, -0.5, 6)
    state = lambda t: (HOME + v0 * t + a * t * t / 2, v0 + a * t)  # noqa: E731
    t1, t0, t = 0.010, 0.012, 0.0155
    out = extrapolate(round(t * 1e9), (round(t0 * 1e9), *state(t0)), (round(t1 * 1e9), *state(t1)))
    np.testing.assert_allclose(out.q, state(t)[0], atol=1e-12)
    np.testing.assert_allclose(out.qd, state(t)[1], atol=1e-12)
    np.testing.assert_allclose(out.qdd, a, atol=1e-9)
    assert out.ahead_s == pytest.approx(0.0035)


def test_the_spread_stays_at_its_floor_while_the_acceleration_holds_and_grows_when_it_steps():
    spread = AccelerationSpread(6, margin=2.0, floor=0.05, moving_s=0.05)
    a = np.full(6, 3.0)
    for k in range(50):  # 500 Hz at constant acceleration: each sample as foretold
        spread.observe(k * 2 * MS, a * k * 0.002)
        assert spread.ready == (k * 0.002 * 3.0 > 0.05 and spread.moved_s >= 0.05)  # moving for 50 ms
    np.testing.assert_allclose(spread.spread, 0.05)
    qd = a * 49 * 0.002
    for k in range(50, 53):  # the acceleration steps by +5 rad/s^2 on joint 2 at the 50th sample
        qd = qd + 0.002 * (a + np.r_[0.0, 0.0, 5.0, 0.0, 0.0, 0.0])
        spread.observe(k * 2 * MS, qd)
    assert spread.spread[2] == pytest.approx(2.0 * 5.0, rel=0.01)  # margin times the step
    np.testing.assert_allclose(np.delete(spread.spread, 2), 0.05, atol=1e-9)


@pytest.fixture(scope="module")
def sensitivities():
    model = ArmModel(SCENE)
    qd = np.full(6, 0.8)
    return wrench_sensitivities(model, "dynamics", HOME, qd, np.ones(6))


def test_the_sensitivities_match_the_model(sensitivities):
    model = ArmModel(SCENE)
    qd, qdd, dq = np.full(6, 0.8), np.ones(6), np.r_[0.0, 1e-3, 0.0, 0.0, 0.0, 0.0]
    base = model.arm_loads(HOME, qd, qdd, "dynamics")[0]
    moved = model.arm_loads(HOME + dq, qd, qdd, "dynamics")[0]
    np.testing.assert_allclose(moved - base, sensitivities.q @ dq, atol=1e-3 * np.abs(moved - base).max())
    faster = model.arm_loads(HOME, qd, qdd + dq * 1e3, "dynamics")[0]
    np.testing.assert_allclose(faster - base, sensitivities.qdd @ (dq * 1e3), rtol=1e-6, atol=1e-9)


def test_the_extrapolation_variance_grows_with_the_gap(sensitivities):
    inv = np.linalg.inv(SCENE.sensor.noise_cov)
    spread = np.full(6, 2.0)
    rows = lambda s, h: extrapolation_rows(sensitivities, s, h, 0.002)  # noqa: E731 - 500 Hz joint samples
    sizes = [quad_sum(rows(spread, h), inv) for h in (0.0, 0.0005, 0.002, 0.005, 0.02)]
    assert all(b > a for a, b in zip(sizes, sizes[1:], strict=False))
    # within half a period only qd's (h^2) and q's (h^4) errors add; past it the acceleration's own grows too
    # (the drift's: 1/2 + h / period, squared in the variance; qd's and q's errors add to it)
    assert sizes[1] - sizes[0] < 1e-3 * sizes[0]
    assert sizes[3] > (0.5 + 2.5) ** 2 * sizes[0]
    assert sizes[4] > ((0.5 + 10.0) / (0.5 + 2.5)) ** 2 * sizes[3]
    assert quad_sum(rows(2 * spread, 0.005), inv) == pytest.approx(4 * sizes[3])


def test_ledger_confirms_an_onset_with_a_contact_within_the_window_and_leaves_others_unconfirmed():
    ledger = ProvisionalLedger(window_ns=20 * MS)
    assert not ledger.provisional(100 * MS)
    assert ledger.judged(95 * MS, False) == (0, [])
    assert ledger.judged(101 * MS, True) == (1, [])  # the pipeline's contact: confirmed
    assert ledger.had_provisional(99 * MS)
    assert not ledger.provisional(500 * MS)
    assert ledger.judged(510 * MS, False) == (0, [])
    assert ledger.judged(521 * MS, False) == (0, [500 * MS])  # judged past the window without a contact
    assert ledger.waiting == 0
    assert not ledger.had_provisional(900 * MS)


def _arm(t: float, step_s: float, jump: np.ndarray):
    """A motion at constant acceleration whose acceleration steps by ``jump`` at ``step_s``: (q, qd, qdd) at t."""
    a, v0 = np.r_[0.5, -0.4, 0.6, 0.0, 0.3, 0.0], np.r_[0.2, 0.1, -0.2, 0.1, 0.0, 0.1]
    q, qd = HOME + v0 * t + a * t * t / 2, v0 + a * t
    if t > step_s:
        h = t - step_s
        q, qd, a = q + jump * h * h / 2, qd + jump * h, a + jump
    return q, qd, a


def test_an_unconfirmed_provisional_onset_gives_its_event():
    """The acceleration steps while the joint samples are 4 ms late: the frames judged at once see the F/T
    sensor's new load on the old acceleration, larger than anything the spread has seen (a provisional onset);
    the confirmed judgement, on the interpolated state with its lag error, sees no contact: the provisional
    onset is said unconfirmed, on events/device, and counted."""
    model = ArmModel(SCENE)
    bus = Bus()
    device, contact = bus.subscribe(EVENTS_DEVICE, maxsize=None), bus.subscribe(EVENTS_CONTACT, maxsize=None)
    monitor = LiveMonitor(bus, SCENE, tare_s=None, publish_inputs=False, settings=settings(level="dynamics"))
    step_s, jump = 1.5, np.r_[0.0, 0.0, 0.0, 0.0, 0.0, 0.0]  # after the spread is identified (1 s of motion)
    jump[1] = 60.0  # rad/s^2 on the shoulder: a sharp change of the motion (ESTIMATE: a stop ramp of a UR)
    pending: deque = deque()
    joint_lag_s = 0.004
    joints = [k * 0.002 for k in range(int(1.7 / 0.002))]
    j = 0
    for i in range(1700):
        t = i * 0.001
        while j < len(joints) and joints[j] + joint_lag_s <= t:
            q, qd, _ = _arm(joints[j], step_s, jump)
            monitor.on_joints(JointFrame.make(round(joints[j] * 1e9), q, qd, np.zeros(6), source="arm", seq=j))
            j += 1
        q, qd, qdd = _arm(t, step_s, jump)
        raw = model.arm_loads(q, qd, qdd, "dynamics")[0]
        monitor.take(pending, [WrenchFrame.make(round(t * 1e9), raw, source="ft", seq=i)], t)
        monitor.judge_ready(pending, t)
    kinds = [e.kind for e in device.drain()]
    assert "provisional_onset" in kinds and "provisional_unconfirmed" in kinds
    assert not [e for e in contact.drain() if e.kind == "onset"]  # the pipeline saw no contact
    assert monitor.counters["provisional_unconfirmed"] == monitor.counters["provisional_onsets"] >= 1
    assert monitor.counters["provisional_frames"] > 600  # from 1 s of motion on


def test_confirmed_judgements_yield_to_a_new_frame_waiting_for_its_provisional_one(monkeypatch):
    """A backlog of frames ready for their confirmed judgement is worked off for at most YIELD_AFTER_NS while a
    new driving frame waits to be taken (and judged provisionally at once): the reflex's onset does not queue
    behind the backlog."""
    monkeypatch.setattr("ftc_hw.monitor.YIELD_AFTER_NS", 0)  # the budget spent after the first frame
    bus = Bus()
    monitor = LiveMonitor(bus, SCENE, tare_s=None, publish_inputs=False, settings=settings(level="dynamics"))
    pending: deque = deque()
    for k in range(60):  # 500 Hz joint state at rest past every frame below
        monitor.on_joints(JointFrame.make(k * 2 * MS, HOME, np.zeros(6), np.zeros(6), source="arm", seq=k))
    raw = ArmModel(SCENE).arm_loads(HOME, np.zeros(6), np.zeros(6), "dynamics")[0]
    monitor.take(pending, [WrenchFrame.make(i * MS, raw, source="ft", seq=i) for i in range(10)], 0.0)
    monitor.backlog = lambda: 1  # a new frame waits in the subscription
    monitor.judge_ready(pending, 0.0)
    assert len(pending) == 9
    monkeypatch.setattr("ftc_hw.monitor.YIELD_AFTER_NS", 10**12)  # within the budget: every ready frame
    monitor.judge_ready(pending, 0.0)
    assert not pending
    assert monitor.counters["frames"] == 10
