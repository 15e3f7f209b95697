"""The evaluation of contact events against ground truth (used by ftc monitor --sim, ftc demo and the
end-to-end tests): detection, delay, false alarms, splits and localization on hand-made timelines."""
from __future__ import annotations

import io
import sys

import pytest
from rich.console import Console

from ftc_hw.app.monitor.evaluate import ContactResult, Evaluation, evaluate
from ftc_hw.app.monitor.view import evaluation_table, make_console
from ftc_hw.scene import builtin_names, load_scene

pytestmark = pytest.mark.compute  # computes only (nothing timed): runs with the others on every core

MS = 1_000_000
T0 = 5_000_000_000  # host ns of the first truth sample


def truth(n: int, contact: set[int], point=(0.1, 0.0, 0.5), link="link3"):
    """One sample per ms; in contact at the given indices."""
    return [{"t": i * 0.001, "t_host_ns": T0 + i * MS, "contact": i in contact,
             "link": link if i in contact else None, "point": list(point) if i in contact else None,
             "force": [0.0, 0.0, -10.0] if i in contact else None} for i in range(n)]


def event(kind: str, t_ns: int, point=(0.1, 0.0, 0.5), link="link3", flags=()):
    return {"t": t_ns / 1e9, "t_host_ns": t_ns, "kind": kind, "link": link, "point": list(point),
            "force": [0.0, 0.0, -10.0], "point_std": [0.001] * 3, "flags": list(flags)}


def test_a_timely_onset_detects_the_contact_and_localization_is_measured():
    tr = truth(400, set(range(100, 200)) | set(range(300, 350)))
    evs = [event("onset", T0 + 101 * MS, point=(0.1, 0.003, 0.5)), event("update", T0 + 150 * MS),
           event("update", T0 + 160 * MS, point=(0.2, 0.0, 0.5), flags=("ambiguous",)),
           event("offset", T0 + 205 * MS),
           event("onset", T0 + 302 * MS + MS // 2), event("offset", T0 + 360 * MS)]
    ev = evaluate(evs, tr, 0.001)
    assert ev.delay_limit_ms == pytest.approx(3.0)
    assert [c.detected for c in ev.contacts] == [True, True]
    assert ev.contacts[0].onset_delay_ms == pytest.approx(1.0)
    assert ev.contacts[1].onset_delay_ms == pytest.approx(2.5) and ev.contacts[1].delay_ok
    assert ev.all_in_time and not ev.false_alarms and ev.splits == 0
    c = ev.contacts[0]
    # the flagged estimate is left out of the accuracy figures, counted in "rms all"
    assert (c.estimates, c.trusted) == (3, 2)
    assert c.err_max_mm == pytest.approx(3.0) and c.err_median_mm == pytest.approx(1.5)
    # errors 3 and 0 mm against a reported |point_std| of sqrt(3) mm
    assert c.err_over_std_rms == pytest.approx((3.0 / 2) ** 0.5, abs=0.005)
    assert c.err_rms_all_mm == pytest.approx(((9 + 0 + 100**2) / 3) ** 0.5, rel=1e-3)
    assert c.link_right == 1.0


def test_a_streams_events_among_the_contacts_are_no_contact_of_their_own():
    tr = truth(400, set(range(100, 200)))
    lost = {"t": (T0 + 150 * MS) / 1e9, "t_host_ns": T0 + 150 * MS, "kind": "sensor_lost", "source": "ft",
            "message": "no F/T frame for 0.258 s"}
    evs = [event("onset", T0 + 101 * MS), lost, event("offset", T0 + 205 * MS, flags=("lost",))]
    ev = evaluate(evs, tr, 0.001)
    assert [c.detected for c in ev.contacts] == [True] and not ev.false_alarms and ev.contacts[0].estimates == 1


def test_an_onset_is_counted_in_the_samples_judged_whatever_their_gaps():
    """A client that took every third sample (and then none for 9 ms): the onset 11 ms after the contact
    began is on the second sample judged in it; the count errs long by the one before the contact."""
    tr = truth(400, set(range(100, 200)) | set(range(300, 350)))
    judged = [T0 + i * MS + MS // 3 for i in list(range(0, 100, 3)) + [102, 111] + list(range(114, 400, 3))]
    evs = [event("onset", T0 + 111 * MS + MS // 3), event("onset", T0 + 303 * MS + MS // 3)]
    ev = evaluate(evs, tr, 0.001, judged_ns=judged)
    assert ev.contacts[0].onset_delay_ms == pytest.approx(11.333, abs=1e-3) and not ev.contacts[0].delay_ok
    # judged in [99, 111.3] ms: 99.3 (before the contact), 102.3, 111.3
    assert [c.onset_samples for c in ev.contacts] == [3, 2]
    assert ev.all_within_samples(3) and not ev.all_within_samples(2)
    assert evaluate(evs, tr, 0.001).contacts[0].onset_samples is None  # not counted without the times
    text = _table_text(ev)
    assert "samples" in text and "one before the contact can count" in " ".join(text.split())


def _table_text(ev: Evaluation) -> str:
    console = Console(width=200, record=True, file=io.StringIO())
    console.print(evaluation_table(ev))
    return console.export_text()


def test_late_missing_false_and_split_onsets_are_reported():
    tr = truth(1000, set(range(100, 200)) | set(range(500, 600)) | set(range(800, 900)))
    evs = [event("onset", T0 + 104 * MS),  # 4 ms: detected, late
           event("onset", T0 + 150 * MS),  # a second onset within the same contact: a split
           event("onset", T0 + 400 * MS),  # no contact there: a false alarm
           event("onset", T0 + 501 * MS)]
    ev = evaluate(evs, tr, 0.001)
    assert [c.detected for c in ev.contacts] == [True, True, False]
    assert not ev.contacts[0].delay_ok and ev.contacts[1].delay_ok
    assert ev.false_alarms == [pytest.approx(0.4)]
    assert ev.splits == 1
    assert not ev.all_in_time
    assert ev.contacts[2].err_rms_mm is None


def test_an_onset_before_the_contact_is_a_false_alarm():
    tr = truth(300, set(range(100, 200)))
    ev = evaluate([event("onset", T0 + 95 * MS)], tr, 0.001)
    assert ev.false_alarms and not ev.contacts[0].detected


def test_truth_without_host_times_is_refused():
    tr = truth(10, set())
    for r in tr:
        del r["t_host_ns"]
    with pytest.raises(ValueError, match="t_host_ns"):
        evaluate([], tr, 0.001)


def test_delay_counts_from_when_the_sample_was_due_when_the_world_ran_late():
    tr = truth(300, set(range(100, 200)))
    for r in tr:
        r["t_due_ns"] = r["t_host_ns"] - 4 * MS  # published 4 ms late
    ev = evaluate([event("onset", T0 + 97 * MS)], tr, 0.001)  # 1 ms after the first sample was due
    c = ev.contacts[0]
    assert c.onset_delay_due_ms == pytest.approx(1.0) and c.onset_delay_ms == pytest.approx(-3.0)
    assert ev.all_in_time and not ev.false_alarms
    # before it was due: a false alarm
    assert evaluate([event("onset", T0 + 94 * MS)], tr, 0.001).false_alarms


def test_each_contact_error_is_set_against_its_cramer_rao_bound():
    tr = truth(300, set(range(100, 200)))
    evs = [event("onset", T0 + 101 * MS, point=(0.1, 0.003, 0.5)), event("update", T0 + 150 * MS),
           event("update", T0 + 160 * MS, point=(0.2, 0.0, 0.5), flags=("ambiguous",))]
    ev = evaluate(evs, tr, 0.001, crlb=lambda rec: 2.0 if rec["contact"] else None)
    c = ev.contacts[0]
    assert c.crlb_rms_mm == pytest.approx(2.0)  # over the two unflagged estimates
    assert ev.worst_rms_to_crlb() == pytest.approx(c.err_rms_mm / 2.0)


def test_the_cramer_rao_bound_of_a_truth_record(contacts):
    """A 50 N push on leng2016: a bound of a fraction of a millimetre to a few (the solver bench's
    scale for this scene); no contact, no bound."""
    from types import SimpleNamespace

    import numpy as np

    from ftc_hw.app.monitor.evaluate import crlb_of_truth
    from ftc_hw.model import ArmModel
    from ftc_hw.scene import load_scene
    from ftc_hw.sim_devices.world.truth import truth_record

    scene = load_scene("leng2016")
    q = np.array(scene.robot.home)
    bound = crlb_of_truth(scene)
    assert bound({"t": 0.0, "contact": False, "contacts": [], "q": list(q)}) is None
    sp, force = contacts(ArmModel(scene), q, 1, seed=3, max_angle_deg=20, f_range=(50.0, 50.0))[0]
    contact = SimpleNamespace(link=sp.link, point=sp.point, force=force, source="probe", label="")
    b = bound(truth_record(SimpleNamespace(t=0.0, q=q, contacts=(contact,))))
    assert b is not None and 0.01 < b < 5.0, b


def test_each_estimate_is_set_against_its_own_bound():
    """Errors of 3 mm where the bound is 1 mm and of 10 mm where it is 10 mm: the RMS error over the
    RMS bound (1.04) hides the 3-sigma estimate; the RMS of error over bound (2.24) shows it. An
    estimate without a bound counts in neither."""
    tr = truth(300, set(range(100, 200)))
    evs = [event("onset", T0 + 101 * MS, point=(0.1, 0.003, 0.5)),
           event("update", T0 + 150 * MS, point=(0.1, 0.01, 0.5)),
           event("update", T0 + 170 * MS, point=(0.1, 0.05, 0.5))]
    bounds = {101: 1.0, 150: 10.0}
    ev = evaluate(evs, tr, 0.001, crlb=lambda rec: bounds.get(round(rec["t"] * 1000)))
    c = ev.contacts[0]
    assert c.crlb_rms_mm == pytest.approx(((1 + 100) / 2) ** 0.5, abs=0.01)
    assert c.err_over_crlb_rms == pytest.approx(((9 + 1) / 2) ** 0.5, abs=0.01)
    assert ev.worst_err_over_crlb() == c.err_over_crlb_rms


def test_the_solvers_own_error_at_a_truth_record(contacts):
    """A 50 N push on leng2016, 400 draws of the scene's noise: the solver's own RMS error is that
    point's Cramer-Rao bound (within the draws' scatter), the same on a second call (seeded by the
    record's time); no contact, no figure."""
    from types import SimpleNamespace

    import numpy as np

    from ftc_hw.app.monitor.evaluate import crlb_of_truth, solver_rms_of_truth
    from ftc_hw.model import ArmModel
    from ftc_hw.scene import load_scene
    from ftc_hw.sim_devices.world.truth import truth_record

    scene = load_scene("leng2016")
    q = np.array(scene.robot.home)
    own = solver_rms_of_truth(scene, draws=400)
    assert own({"t": 0.0, "contact": False, "contacts": [], "q": list(q)}) is None
    sp, force = contacts(ArmModel(scene), q, 1, seed=3, max_angle_deg=20, f_range=(50.0, 50.0))[0]
    contact = SimpleNamespace(link=sp.link, point=sp.point, force=force, source="probe", label="")
    rec = truth_record(SimpleNamespace(t=0.25, q=q, contacts=(contact,)))
    rms, bound = own(rec), crlb_of_truth(scene)(rec)
    assert rms == own(rec)
    assert 0.8 * bound < rms < 1.25 * bound, (rms, bound)


def test_each_contact_is_set_against_the_solvers_own_error():
    """Errors of 3 mm and 1 mm where the solver alone makes 2 mm: 1.12 (sqrt(5)/2); a flagged
    estimate counts in neither."""
    tr = truth(300, set(range(100, 200)))
    evs = [event("onset", T0 + 101 * MS, point=(0.1, 0.003, 0.5)),
           event("update", T0 + 150 * MS, point=(0.1, 0.001, 0.5)),
           event("update", T0 + 170 * MS, point=(0.1, 0.05, 0.5), flags=["ambiguous"])]
    ev = evaluate(evs, tr, 0.001, solver_rms=lambda rec: 2.0)
    c = ev.contacts[0]
    assert c.solver_rms_mm == pytest.approx(2.0)
    assert c.err_over_solver == pytest.approx(5 ** 0.5 / 2, abs=0.01)
    assert ev.worst_err_over_solver() == c.err_over_solver


def test_a_contact_the_run_ends_in_is_marked_cut_and_can_be_left_out_of_the_worst():
    tr = truth(400, set(range(100, 200)) | set(range(350, 400)))  # the second still on at the end
    evs = [event("onset", T0 + 101 * MS), event("update", T0 + 150 * MS, point=(0.1, 0.002, 0.5)),
           event("offset", T0 + 205 * MS),
           event("onset", T0 + 351 * MS, point=(0.1, 0.009, 0.5))]
    ev = evaluate(evs, tr, 0.001)
    assert [c.cut for c in ev.contacts] == [False, True]
    assert ev.worst_rms_mm() == pytest.approx(9.0)
    assert ev.worst_rms_mm(whole=True) == pytest.approx(2 ** 0.5, abs=0.01)  # errors 0 and 2 mm
    assert [c.index for c in ev.judged(whole=True)] == [1] and len(ev.judged()) == 2


def _worst_case_evaluation() -> Evaluation:
    """Every column at its widest: the longest link names of the built-in scenes, 4-digit errors, a cut,
    a late, a missed contact and false alarms."""
    def contact(i, link, est_link, detected=True, delay_ok=True, cut=False):
        return ContactResult(i, 1234.567, 1235.0, link, 123.45 if detected else None, 123.45 if detected else None,
                             delay_ok, 3, 1234, 1234, est_link, 1.0, 1234.5, 1234.5, 1234.5, 1234.5, 123.45,
                             crlb_rms_mm=1234.5, err_over_crlb_rms=12.34, solver_rms_mm=123.4, err_over_solver=12.34,
                             err_over_std_rms=12.34, cut=cut)
    links = sorted({t.link for name in builtin_names() for t in load_scene(name).touchable}, key=len)[::-1]
    contacts = [contact(10, links[0], links[1], cut=True), contact(11, links[1], links[0], delay_ok=False),
                contact(12, links[2], "-", detected=False)]
    return Evaluation(contacts, [1.234, 5.678], 2, 0.001, 40.0, 99, 5000)


def _headers_and_links_whole(text: str, ev: Evaluation) -> None:
    assert "…" not in text and "..." not in text, text
    for column in ("#", "start s", "true link", "detected", "delay ms", "from due", "est. link", "link ok",
                   "err mm med", "rms", "CRLB rms", "err/CRLB", "err/solver", "err/std", "max", "rms all", "|dF| N",
                   "estimates"):
        assert column in text, (column, text)
    for c in ev.contacts:  # each row's link names on one line, whole
        row = next(line for line in text.splitlines() if line.split()[:1] == [str(c.index)] and c.link in line)
        assert c.est_link in row and "1234.567" in row, (row, text)
    assert "late" in text and "cut" in text


def test_the_ground_truth_table_reads_whole_at_100_columns_and_in_a_file(monkeypatch):
    ev = _worst_case_evaluation()
    terminal = Console(width=100, record=True, file=io.StringIO(), force_terminal=True)
    terminal.print(evaluation_table(ev))
    text = terminal.export_text()
    assert max(len(line.rstrip()) for line in text.splitlines()) <= 100
    _headers_and_links_whole(text, ev)
    # written to a file or a pipe: the console the monitor's report prints with
    out = io.StringIO()
    monkeypatch.setattr(sys, "stdout", out)
    console = make_console()
    assert not console.is_terminal
    console.print(evaluation_table(ev))
    _headers_and_links_whole(out.getvalue(), ev)


def test_a_scripted_contact_s_kind_is_scored_against_its_final_class():
    tr = truth(400, set(range(100, 200)) | set(range(300, 350)))
    for i in range(100, 200):
        tr[i]["contacts"] = [{"link": "link3", "point": [0.1, 0.0, 0.5], "force": [0.0, 0.0, -10.0],
                              "source": "obstacle", "class": "clamping"}]
    for i in range(300, 350):
        tr[i]["contacts"] = [{"link": "link3", "point": [0.1, 0.0, 0.5], "force": [0.0, 0.0, -10.0],
                              "source": "probe", "class": "guidance"}]

    def classified(kind, t_ns, cid, cls, intent):
        return event(kind, t_ns) | {"contact_id": cid, "contact_class": cls, "intent": intent}

    evs = [classified("onset", T0 + 101 * MS, 1, "unknown", "unknown"),
           classified("offset", T0 + 205 * MS, 1, "quasi_static", "impact"),
           classified("onset", T0 + 301 * MS, 2, "unknown", "unknown"),
           classified("offset", T0 + 355 * MS, 2, "quasi_static", "impact")]
    ev = evaluate(evs, tr, 0.001)
    assert [(c.true_class, c.classified, c.class_right) for c in ev.contacts] == [
        ("clamping", "quasi_static/impact", True), ("guidance", "quasi_static/impact", False)]
    # a truth without kinds, events without classes: nothing scored
    plain = evaluate([event("onset", T0 + 101 * MS), event("offset", T0 + 205 * MS)], truth(400, set(range(100, 200))),
                     0.001)
    assert (plain.contacts[0].true_class, plain.contacts[0].class_right) == (None, None)
