"""Contact events against the simulated world's ground truth (``ftc monitor --sim``, ``ftc demo``, tests).

Both sides are on the host's monotonic clock: events by their ``t_host_ns`` (the F/T sample's aligned
time), truth by the ``t_host_ns`` at which the world published each sample to its emulators.

* A true contact is a run of truth samples in contact (runs less than ``merge_gap_s`` apart are one).
* It is detected when an onset event falls within ``[due - early_s, end + late_s]``, ``due`` being
  the host time at which the contact's first sample was due (``t_due_ns``; the world publishes it
  then, or later when it runs behind on a loaded machine). Its delay is the onset's time minus the
  host time at which that sample was published (``t_host_ns``: from then on the devices can know
  it); in time when at most ``delay_samples`` sensor periods plus ``delay_extra_s``. A device with
  its own clock has its frames placed on the host clock as if delivered with the least delay seen
  (the world's least lateness included), so on a late world the delay from publication can be
  slightly negative; ``onset_delay_due_ms`` (from the due time) bounds it from above.
* Given the host times of the samples the monitor judged (``judged_ns``: its inputs' ``t_host_ns``,
  the recording's ``monitor/input``), each onset is also counted in samples (``onset_samples``): how
  many judged samples have times from one sample period before the contact's first sample was due to
  the onset's (the onset's own the last). The sample before the contact can count too (its time is
  its delivery, or its device time placed on the host clock, which falls between the two), so the
  count errs long by at most one. A client that drops a device's samples, or a loaded host that
  delivers them late, stretches the delay in ms, not this count: it is the detector's own figure,
  whatever the transport did.
* An onset that belongs to no true contact is a false alarm; a second onset within one contact is
  counted as a split. Events after the truth's last sample are not judged.
* Localization: every onset/update event with an estimate, at a time when the truth is in contact,
  against the truth's strongest contact at the newest sample published before the event (the sample
  the device sent): distance of the points (mm), of the forces (N), and whether the link is right.
  As in the solver's benchmark, the accuracy figures are over the estimates the solver gives without
  a flag (``ambiguous``, ``grazing``, ``off_surface``, ... are the solver saying it cannot be sure);
  ``err_rms_all_mm`` includes the flagged ones. ``err_over_crlb_rms``: the RMS of each estimate's
  error over its own Cramer-Rao bound (about 1 at the statistical limit). It is the fair per-contact
  figure: a contact's few low-force samples (onset, release) have bounds of centimetres, and in the
  ratio of the RMS error to the RMS bound they swamp the rest either way.
* ``err_over_solver``: the RMS error over the solver's own RMS error at the same truth samples, when
  it is given the true contact wrench plus the scene's sensor noise and nothing else (``draws``
  noise draws per sample, its unflagged answers): what one frame can do. The events carry the
  contact's point fused over its frames (:mod:`ftc_hw.tracking`), so this and ``err/CRLB`` fall
  below 1 by what the fusion gains; near an edge (a cylinder's rim), where the local Cramer-Rao
  bound misses the other face's mode, this is the figure that still says what one frame can do.
* ``cut``: the truth is still in contact at its last sample (the run ended during the contact). Its
  figures rest on the few estimates before the end, the contact's track barely started; the
  ``worst_*`` figures can leave such contacts out (``whole=True``).
* ``err_over_std_rms``: the RMS of each estimate's error over the uncertainty it reports itself
  (|point error| / |point_std|): about 1 when the reported uncertainty is honest, above 1 when it
  claims more than it has.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from ftc_hw.bus import CONTACT_KINDS
from ftc_hw.model import ArmModel, Contact
from ftc_hw.sim_devices.world.contact_kinds import EXPECTED_CLASS
from ftc_hw.solver import ContactSolver
from ftc_hw.solver.bound import crlb_point_cov


@dataclass
class ContactResult:
    index: int
    start_s: float  # simulated time of the first sample in contact
    end_s: float
    link: str  # the true link (most samples)
    onset_delay_ms: float | None  # from the first contact sample's publication; None: not detected
    onset_delay_due_ms: float | None  # from its due time
    delay_ok: bool
    onsets: int
    estimates: int  # onset/update events with an estimate while the truth is in contact
    trusted: int  # of which without a flag
    est_link: str
    link_right: float  # fraction of the unflagged estimates on the true link
    err_median_mm: float | None  # point error of the unflagged estimates
    err_rms_mm: float | None
    err_max_mm: float | None
    err_rms_all_mm: float | None  # every estimate, flagged or not
    force_err_median_n: float | None
    crlb_rms_mm: float | None = None  # Cramer-Rao bound of the same samples' truth (the floor for err_rms_mm)
    err_over_crlb_rms: float | None = None  # RMS of error / bound over the unflagged estimates with a bound
    solver_rms_mm: float | None = None  # the solver's RMS error on the same samples' true wrench + sensor noise
    err_over_solver: float | None = None  # RMS error / solver_rms_mm, over the same estimates
    err_over_std_rms: float | None = None  # RMS of |error| / |reported point_std| over the unflagged estimates
    cut: bool = False  # still in contact at the truth's last sample: the run ended during it
    true_class: str | None = None  # the scripted contact's kind the truth says (clamping, guidance, impact)
    classified: str | None = None  # the final class of the contact reported first in it: "contact_class/intent"
    class_right: bool | None = None  # that class is the kind's (EXPECTED_CLASS); None: no kind said or not reported
    onset_samples: int | None = None  # the onset's sample: the how-manieth judged since the contact began (judged_ns)

    @property
    def detected(self) -> bool:
        return self.onset_delay_ms is not None


@dataclass
class Evaluation:
    contacts: list[ContactResult]
    false_alarms: list[float]  # simulated times of onsets outside every true contact
    splits: int
    sample_period_s: float
    delay_limit_ms: float
    events: int
    truth_samples: int
    notes: list[str] = field(default_factory=list)

    @property
    def detected(self) -> int:
        return sum(c.detected for c in self.contacts)

    @property
    def all_in_time(self) -> bool:
        return all(c.detected and c.delay_ok for c in self.contacts)

    def all_within_samples(self, n: int) -> bool:
        """Every contact detected on at most its ``n``-th judged sample (evaluated with ``judged_ns``)."""
        return all(c.onset_samples is not None and c.onset_samples <= n for c in self.contacts)

    def judged(self, whole: bool = False) -> list[ContactResult]:
        """The contacts, or with ``whole`` only those the run saw to their end (a contact cut by the
        run's end has few estimates, the track's first ones: its figures are those of a few frames)."""
        return [c for c in self.contacts if not (whole and c.cut)]

    def worst_rms_mm(self, whole: bool = False) -> float | None:
        errs = [c.err_rms_mm for c in self.judged(whole) if c.err_rms_mm is not None]
        return max(errs) if errs else None

    def worst_rms_to_crlb(self, whole: bool = False) -> float | None:
        """The largest per-contact ratio of the RMS point error to its Cramer-Rao bound."""
        r = [c.err_rms_mm / c.crlb_rms_mm for c in self.judged(whole) if c.err_rms_mm is not None and c.crlb_rms_mm]
        return max(r) if r else None

    def worst_err_over_crlb(self, whole: bool = False) -> float | None:
        """The largest per-contact RMS of the point error over its own Cramer-Rao bound."""
        r = [c.err_over_crlb_rms for c in self.judged(whole) if c.err_over_crlb_rms is not None]
        return max(r) if r else None

    def worst_err_over_solver(self, whole: bool = False) -> float | None:
        """The largest per-contact RMS point error over the solver's own on the same samples."""
        r = [c.err_over_solver for c in self.judged(whole) if c.err_over_solver is not None]
        return max(r) if r else None

    def worst_err_over_std(self, whole: bool = False) -> float | None:
        """The largest per-contact RMS of the point error over the uncertainty the events report."""
        r = [c.err_over_std_rms for c in self.judged(whole) if c.err_over_std_rms is not None]
        return max(r) if r else None

    def to_dict(self) -> dict[str, Any]:
        return {"contacts": [asdict(c) for c in self.contacts], "detected": self.detected,
                "false_alarms": self.false_alarms, "splits": self.splits, "sample_period_s": self.sample_period_s,
                "delay_limit_ms": self.delay_limit_ms, "events": self.events, "truth_samples": self.truth_samples}


def _class_of(records: list[dict[str, Any]], offset: dict[str, Any] | None) -> tuple[str | None, str | None,
                                                                                    bool | None]:
    """An episode's scripted kind (the truth's ``class``, most samples), the final class of the contact
    reported in it (its offset's) and whether that is the kind's."""
    kinds = [c["class"] for r in records for c in r.get("contacts", ()) if c.get("class")]
    kind = max(set(kinds), key=kinds.count) if kinds else None
    if offset is None or not offset.get("contact_class"):
        return kind, None, None
    got = (offset["contact_class"], offset.get("intent", ""))
    return kind, "/".join(got), (got == EXPECTED_CLASS[kind]) if kind in EXPECTED_CLASS else None


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x ** 2)))


def _episodes(t: np.ndarray, contact: np.ndarray, merge_gap_s: float) -> list[tuple[int, int]]:
    """(first, last) truth indices of each contact."""
    out: list[list[int]] = []
    for i in np.flatnonzero(contact):
        if out and t[i] - t[out[-1][1]] <= merge_gap_s:
            out[-1][1] = int(i)
        else:
            out.append([int(i), int(i)])
    return [(a, b) for a, b in out]


def evaluate(events: list[dict[str, Any]], truth: list[dict[str, Any]], sample_period_s: float, *,
             delay_samples: int = 2, delay_extra_s: float = 0.001, merge_gap_s: float = 0.05,
             early_s: float = 0.001, late_s: float = 0.05,
             crlb: Callable[[dict[str, Any]], float | None] | None = None,
             solver_rms: Callable[[dict[str, Any]], float | None] | None = None,
             judged_ns: np.ndarray | None = None) -> Evaluation:
    """``events``: event records (:func:`ftc_hw.record.events.event_record`); ``truth``: truth records
    with ``t_host_ns``; ``judged_ns``: shape (n,), the host times (ns) of the samples the monitor judged,
    to count each onset in samples; ``crlb``: the Cramer-Rao bound (mm) of a truth record's contact
    (:func:`crlb_of_truth`), to set each contact's error against what the sensor noise allows;
    ``solver_rms``: the solver's own RMS error (mm) there under that noise (:func:`solver_rms_of_truth`)."""
    if truth and "t_host_ns" not in truth[0]:
        raise ValueError("the truth records carry no t_host_ns: write them with ftc monitor --sim --truth")
    th = np.array([r["t_host_ns"] for r in truth], dtype=np.int64)
    due = np.array([r.get("t_due_ns", r["t_host_ns"]) for r in truth], dtype=np.int64)
    ts = np.array([r["t"] for r in truth], dtype=float)
    contact = np.array([bool(r["contact"]) for r in truth])
    episodes = _episodes(ts, contact, merge_gap_s)
    ep_of = np.full(len(truth), -1)
    for k, (a, b) in enumerate(episodes):
        ep_of[a:b + 1] = k
    limit_ns = int(round((delay_samples * sample_period_s + delay_extra_s) * 1e9))
    judged = None if judged_ns is None else np.sort(np.asarray(judged_ns, dtype=np.int64))
    period_ns = int(round(sample_period_s * 1e9))
    early, late = int(early_s * 1e9), int(late_s * 1e9)

    def sim_time(t_ns: int) -> float:
        return float(np.interp(t_ns, th, ts)) if len(th) else float("nan")

    first_onset: dict[int, int] = {}
    first_id: dict[int, int] = {}  # the contact id of each episode's first onset
    final: dict[int, dict[str, Any]] = {}  # each contact id's offset
    onsets_in: dict[int, int] = {}
    false_alarms: list[float] = []
    # (point err mm, force err N, link, flagged, bound mm or None, solver's RMS error mm or None,
    #  reported |point_std| mm)
    errs: dict[int, list[tuple[float, float, str, bool, float | None, float | None, float]]] = {}
    evs = sorted(events, key=lambda e: e["t_host_ns"])
    t_last = int(th[-1]) if len(th) else 0
    for ev in evs:
        if ev["kind"] not in CONTACT_KINDS:
            continue  # a stream's event (sensor_lost, ...): no contact to judge
        t = int(ev["t_host_ns"])
        if t > t_last:
            continue  # after the truth ends (the world's post-roll): nothing to judge it against
        if ev["kind"] == "onset":
            k = next((k for k, (a, b) in enumerate(episodes) if due[a] - early <= t <= th[b] + late), None)
            if k is None:
                false_alarms.append(round(sim_time(t), 4))
            else:
                onsets_in[k] = onsets_in.get(k, 0) + 1
                first_onset.setdefault(k, t)
                first_id.setdefault(k, ev.get("contact_id", 0))
        if ev["kind"] == "offset":
            final[ev.get("contact_id", 0)] = ev
        # an offset repeats the last estimate, an exceedance the event that crossed its limit
        if ev["kind"] in ("offset", "exceedance") or not ev["link"] or "no_estimate" in ev["flags"]:
            continue
        i = int(np.searchsorted(th, t, side="right")) - 1
        if i < 0 or not contact[i]:
            continue
        k = int(ep_of[i])
        rec = truth[i]
        trusted = not ev["flags"]
        errs.setdefault(k, []).append((float(np.linalg.norm(np.subtract(ev["point"], rec["point"]))) * 1e3,
                                       float(np.linalg.norm(np.subtract(ev["force"], rec["force"]))), ev["link"],
                                       not trusted, crlb(rec) if crlb is not None and trusted else None,
                                       solver_rms(rec) if solver_rms is not None and trusted else None,
                                       float(np.linalg.norm(ev.get("point_std", (0.0, 0.0, 0.0)))) * 1e3))

    results = []
    for k, (a, b) in enumerate(episodes):
        true_links = [truth[i]["link"] for i in range(a, b + 1) if truth[i]["contact"]]
        link = max(set(true_links), key=true_links.count)
        delay = float(first_onset[k] - th[a]) / 1e6 if k in first_onset else None
        delay_due = float(first_onset[k] - due[a]) / 1e6 if k in first_onset else None
        onset_samples = (_samples_between(judged, int(due[a]) - period_ns, first_onset[k])
                         if judged is not None and k in first_onset else None)
        rows = errs.get(k, [])
        good = [r for r in rows if not r[3]]
        true_class, classified, class_right = _class_of(truth[a:b + 1], final.get(first_id.get(k, -1)))
        e = np.array([r[0] for r in good])
        est = [r[2] for r in good]

        def stat(x: np.ndarray, f) -> float | None:
            return round(float(f(x)), 2) if len(x) else None

        ref = [r for r in good if r[5] is not None]
        ref_err, ref_rms = np.array([r[0] for r in ref]), np.array([r[5] for r in ref])

        results.append(ContactResult(
            index=k + 1, start_s=round(float(ts[a]), 4), end_s=round(float(ts[b]), 4), link=link,
            onset_delay_ms=None if delay is None else round(delay, 3),
            onset_delay_due_ms=None if delay_due is None else round(delay_due, 3),
            delay_ok=bool(delay is not None and delay * 1e6 <= limit_ns), onsets=onsets_in.get(k, 0),
            estimates=len(rows), trusted=len(good), est_link=max(set(est), key=est.count) if est else "-",
            link_right=round(sum(x == link for x in est) / len(est), 3) if est else 0.0,
            err_median_mm=stat(e, np.median), err_rms_mm=stat(e, _rms), err_max_mm=stat(e, np.max),
            err_rms_all_mm=stat(np.array([r[0] for r in rows]), _rms),
            force_err_median_n=stat(np.array([r[1] for r in good]), np.median),
            crlb_rms_mm=stat(np.array([r[4] for r in good if r[4] is not None]), _rms),
            err_over_crlb_rms=stat(np.array([r[0] / r[4] for r in good if r[4]]), _rms),
            solver_rms_mm=stat(ref_rms, _rms),
            err_over_solver=(round(float(_rms(ref_err) / _rms(ref_rms)), 2) if len(ref) and _rms(ref_rms) > 0
                             else None),
            err_over_std_rms=stat(np.array([r[0] / r[6] for r in good if r[6] > 0]), _rms),
            cut=bool(b == len(truth) - 1), true_class=true_class, classified=classified, class_right=class_right,
            onset_samples=onset_samples))
    splits = sum(max(0, n - 1) for n in onsets_in.values())
    return Evaluation(results, false_alarms, splits, sample_period_s, limit_ns / 1e6, len(events), len(truth))


def _samples_between(judged: np.ndarray, start_ns: int, onset_ns: int) -> int:
    """How many judged samples fall in [start_ns, onset_ns]: the onset's own is the last of them."""
    return int(np.searchsorted(judged, onset_ns, side="right") - np.searchsorted(judged, start_ns, side="left"))


def _reading_of_truth(scene) -> Callable[[dict[str, Any]], tuple | None]:
    """For a truth record in contact: (solver, q, its noise-free compensated reading, the solver's
    estimate of it, the true point); None when the estimate does not give back the true point (below
    the noise floor, or another link's crossing ranked first)."""
    model = ArmModel(scene)
    solver = ContactSolver(model)

    def reading(rec: dict[str, Any]) -> tuple | None:
        if not rec.get("contact") or rec.get("q") is None:
            return None
        q = np.asarray(rec["q"], dtype=float)
        contacts = [Contact(c["link"], c["point"], c["force"]) for c in rec["contacts"]]
        clean = model.predicted_wrench(q, level="bias", contacts=contacts)
        e = solver.solve(clean, q)
        true_point = np.asarray(rec["point"], dtype=float)
        if not e.contact or float(np.linalg.norm(e.point - true_point)) > 1e-6:
            return None
        return solver, q, clean, e, true_point

    return reading


def crlb_of_truth(scene) -> Callable[[dict[str, Any]], float | None]:
    """The Cramer-Rao bound (mm, RMS over the surface's two directions) of a truth record's contacts:
    the 6-D wrench measurement under the scene's sensor noise, the point constrained to the surface
    (as ``ftc bench solver`` computes it). None when the noise-free reading does not give back the
    true point (below the noise floor, or another link's crossing ranked first); a noise-free reading
    flagged only ``ambiguous`` (a neighbour within the line's noise) still has its bound: the noisy
    estimates of it that come unflagged are scored against it."""
    reading = _reading_of_truth(scene)

    def bound(rec: dict[str, Any]) -> float | None:
        r = reading(rec)
        if r is None:
            return None
        solver, _q, _clean, e, true_point = r
        return math.sqrt(np.trace(crlb_point_cov(solver, true_point, e.normal, e.force))) * 1e3

    return bound


def solver_rms_of_truth(scene, draws: int = 100, seed: int = 0) -> Callable[[dict[str, Any]], float | None]:
    """The solver's own RMS point error (mm) at a truth record's contacts: the true contact wrench plus
    ``draws`` draws of the scene's sensor noise, solved at the true q, over the answers it gives
    without a flag (as the live figures count them). None where the noise-free reading does not give
    back the true point (as :func:`crlb_of_truth`) or no draw comes unflagged. Draws are seeded by the
    record's time, so an evaluation repeats exactly."""
    reading = _reading_of_truth(scene)
    std = np.sqrt(np.diag(np.asarray(scene.sensor.noise_cov, dtype=float)))

    def rms_error(rec: dict[str, Any]) -> float | None:
        r = reading(rec)
        if r is None:
            return None
        solver, q, clean, _e, true_point = r
        rng = np.random.default_rng([seed, int(round(float(rec["t"]) * 1e6))])
        b = solver.solve_batch(clean + rng.normal(size=(draws, 6)) * std, np.repeat(q[None], draws, axis=0))
        ok = b.contact & (b.flags == 0)
        if not ok.any():
            return None
        return float(np.sqrt(np.mean(np.sum((b.point[ok] - true_point) ** 2, axis=1)))) * 1e3

    return rms_error
