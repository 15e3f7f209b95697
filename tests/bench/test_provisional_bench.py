"""``ftc bench provisional``'s bookkeeping: the arrival order it delivers in, and its judgement of onsets
against the truth (false alarms, the first onset of each contact and its decision delay)."""
from __future__ import annotations

import numpy as np
import pytest

from ftc_hw.bench.provisional import Arrivals, Streams, _arrival_order, judge

pytestmark = pytest.mark.compute

MS = 1_000_000


def _streams() -> Streams:
    t = np.arange(1000, dtype=np.int64) * MS  # 1 kHz for 1 s; in contact from 300 to 400 ms
    contact = (t >= 300 * MS) & (t < 400 * MS)
    jt = np.arange(500, dtype=np.int64) * 2 * MS
    z = np.zeros((500, 6))
    return Streams(t, np.zeros((1000, 6)), np.zeros(1000, bool), contact, jt, z, z, z)


def test_arrivals_leave_missed_joint_samples_out_and_come_in_order():
    s = _streams()
    missed = np.zeros(7, bool)
    missed[3] = True
    order = _arrival_order(s, Arrivals(np.array([1 * MS, 3 * MS]), missed, np.array([MS // 10]), "test"))
    joints = [i for _, kind, i in order if kind == 0]
    assert 3 not in joints and 10 not in joints and 4 in joints and len(joints) == 500 - 71  # every 7th from the 3rd
    assert [a for a, _, _ in order] == sorted(a for a, _, _ in order)


def test_judge_counts_false_alarms_and_the_first_onset_of_each_contact():
    s = _streams()
    off = MS // 10  # the aligned clock is the device's plus the least F/T delay
    events = [("provisional_onset", 300 * MS + off, 301 * MS + 3 * off),  # decided 1.2 ms after its sample
              ("onset", 300 * MS + off, 304 * MS),  # the confirmed one, later
              ("provisional_onset", 800 * MS + off, 801 * MS),  # nothing touched the arm then
              ("provisional_unconfirmed", 800 * MS + off, 830 * MS)]
    out = judge(s, {"events": events, "counters": {"provisional_unconfirmed": 1}, "offset_ns": off})
    assert (out["contacts"], out["detected"], out["first_provisional"]) == (1, 1, 1)
    assert (out["false_provisional"], out["false_confirmed"], out["provisional_unconfirmed"]) == (1, 0, 1)
    assert out["decision_ms_median"] == pytest.approx(1.2)
    assert out["false_provisional_t_s"] == [0.8]
