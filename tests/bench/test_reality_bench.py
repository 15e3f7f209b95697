"""``ftc bench reality``'s bookkeeping on made-up runs: false alarms outside true contacts, detection of
the contacts above 10 N only, errors and coverage over the unflagged events, the worst draw."""
from __future__ import annotations

import numpy as np
import pytest

from ftc_hw.bench.reality import ALL_COLUMNS, _combine, _summarize, select_columns
from ftc_hw.sim_devices.world import DIFFERENCES


def _run(onsets, points, contact_spans=((1.0, 1.3, 30.0), (2.0, 2.3, 5.0))):
    t = np.arange(0.0, 4.0, 0.001)
    contact = np.zeros_like(t, dtype=bool)
    force = np.zeros_like(t)
    for a, b, f in contact_spans:
        inside = (t >= a) & (t <= b)
        contact |= inside
        force[inside] = f
    return {"t": t, "contact": contact, "force": force, "resid": np.tile([0.3, 0.4, 0.0, 0.01, 0.0, 0.0], (10, 1)),
            "stat": np.linspace(0.0, 10.0, 100), "onsets": list(onsets), "points": list(points), "threshold": 50.0}


def test_summary_counts_what_the_issue_asks():
    free = _run([0.5], [], contact_spans=())  # one alarm with nothing touching
    # (error as answered, covered, right link, unflagged, error on the primitives, the line missed the meshes,
    # the true force, N)
    hits = _run([1.002, 2.004, 3.5], [(2.0, True, True, True, 1.0, False, 30.0),
                                      (4.0, False, True, True, 4.0, True, 5.0),
                                      (90.0, False, False, False, 5.0, False, 30.0)])
    s = _summarize(free, [hits])
    assert s["false_alarms"] == 2  # 0.5 s in the free run, 3.5 s in the contact run
    assert s["contacts_over_10N"] == 1 and s["detected_over_10N"] == 1  # the 5 N contact is not counted
    assert abs(s["delay_ms_median"] - 3.0) < 1e-9  # (2 + 4) / 2 ms: every detected contact's delay
    assert s["pos_err_mm_median"] == 3.0 and s["coverage95"] == 0.5  # unflagged only: 2 and 4 mm
    assert abs(s["flagged_share"] - 1 / 3) < 1e-12 and abs(s["link_right"] - 2 / 3) < 1e-12
    # the same events on the primitives: 1 and 4 mm; one line missed its meshes
    assert s["pos_err_mm_median_primitives"] == 2.5 and s["mesh_misses"] == 1
    assert s["pos_err_mm_median_over10N"] == 2.0  # the 5 N event's 4 mm is left out
    assert abs(s["residual_rms_N"] - 0.5) < 1e-12 and abs(s["residual_rms_Nm"] - 0.01) < 1e-12
    worse = dict(s, coverage95=0.2, pos_err_mm_median=9.0)
    c = _combine([s, worse])
    assert c["coverage95_worst"] == 0.2 and c["pos_err_mm_median_worst"] == 9.0 and c["draws"] == 2
    assert c["false_alarms"] == 4 and abs(c["false_alarms_per_min"] - 4 / (2 * s["free_minutes"])) < 1e-12


def test_errors_are_also_split_by_scenario():
    """The sweep's obstacle and the pokes: each run's own figures, as answered and on the primitives."""
    sweep = _run([1.002], [(2.0, True, True, True, 7.0, False, 20.0), (6.0, True, True, True, 9.0, False, 20.0)])
    pokes = _run([1.002], [(10.0, True, True, True, 1.0, False, 20.0), (30.0, True, True, True, None, False, 20.0)])
    s = _summarize(_run([], [], contact_spans=()), [sweep, pokes])
    assert s["pos_err_mm_median_sweep"] == 4.0 and s["pos_err_mm_median_sweep_primitives"] == 8.0
    assert s["pos_err_mm_median_pokes"] == 20.0 and s["pos_err_mm_median_pokes_primitives"] == 1.0  # None: no meshes
    assert s["pos_err_mm_median"] == 8.0  # pooled over both


def test_columns_are_chosen_by_name_or_glob_and_an_unknown_one_is_named():
    assert [c.name for c in select_columns(ALL_COLUMNS, ["ideal", "only:*"])] == (
        ["ideal"] + [f"only:{d}" for d in DIFFERENCES])
    assert select_columns(ALL_COLUMNS, None) == ALL_COLUMNS
    with pytest.raises(ValueError, match="no column matches only:nothing, typo: the columns are ideal"):
        select_columns(ALL_COLUMNS, ["typical", "only:nothing", "typo"])


def test_a_contact_that_comes_while_the_last_one_is_still_reported_is_detected_and_counted_merged():
    spans = ((1.0, 1.3, 30.0), (1.5, 1.8, 30.0), (3.0, 3.3, 30.0))
    held = _run([1.002], [], contact_spans=spans) | {"offsets": [2.0]}  # open over the second touch
    s = _summarize(_run([], [], contact_spans=()), [held])
    assert s["contacts_over_10N"] == 3 and s["detected_over_10N"] == 2 and s["merged_over_10N"] == 1
    assert abs(s["delay_ms_median"] - 2.0) < 1e-9  # the merged one has no onset delay of its own
    # closed before it came, or opened by a false alarm: missed
    closed = _run([1.002], [], contact_spans=spans) | {"offsets": [1.4]}
    alarm = _run([0.5], [], contact_spans=spans) | {"offsets": []}
    for run in (closed, alarm):
        s = _summarize(_run([], [], contact_spans=()), [run])
        assert s["merged_over_10N"] == 0 and s["detected_over_10N"] == (1 if run is closed else 0)
