"""The provisional onset: each F/T frame judged at once, on the joint state extrapolated past the newest joint
sample, for the reflex; the pipeline's own (confirmed) judgement follows on the interpolated state.

:class:`ProvisionalJudge` runs beside a :class:`~ftc_hw.pipeline.contact.ContactPipeline` and never changes
it: it compensates on a twin of the pipeline's model (its own MjData), with the pipeline's bias and gain, and
judges with a detector of its own (the pipeline's noise covariance, threshold and debounce) whose covariance
adds the extrapolation's error rows (:mod:`ftc_hw.compensation.extrapolation`: the identified acceleration
spread through the model's sensitivities, growing with how far ahead the state is) and the identified model's
error rows as the pipeline last computed them. So the confirmed events are the same with or without it.

:class:`ProvisionalLedger` pairs the provisional onsets with the confirmed judgement: one is confirmed when the
pipeline is in contact at a frame within ``window_ns`` of it; once the pipeline has judged past that window
without, it is unconfirmed (the monitor says so: an event of its own).
"""
from __future__ import annotations

from collections import deque

import numpy as np

from ftc_hw.compensation.extrapolation import (
    AccelerationSpread,
    Extrapolated,
    Sensitivities,
    extrapolate,
    extrapolation_rows,
    wrench_sensitivities,
)
from ftc_hw.detection import ContactDetector, Detection

from .contact import ContactPipeline

SENSITIVITY_REFRESH_NS = 10_000_000  # the model's sensitivities change with the pose: recomputed this often
CONFIRM_WINDOW_NS = 20_000_000  # a provisional onset and the pipeline's contact this close: the same contact
Sample = tuple[int, np.ndarray, np.ndarray]  # a joint sample: (time ns, q (n,) rad, qd (n,) rad/s)


class ProvisionalJudge:
    """Judges F/T frames on extrapolated joint states (module docstring). ``spread``: the acceleration spread
    identified from the joint stream (feed it every joint sample)."""

    def __init__(self, pipeline: ContactPipeline, *, spread: AccelerationSpread | None = None) -> None:
        self.pipeline = pipeline
        self.compensator = pipeline.motion.compensator
        self.model = self.compensator.model.twin()
        self.spread = spread or AccelerationSpread(pipeline.scene.n_joints)
        d, s = pipeline.detector, pipeline.settings.detection
        self.detector = ContactDetector(d.cov, p_false=s.p_false, n_on=s.n_on, n_off=s.n_off)
        self._sens: Sensitivities | None = None
        self._sens_t = 0
        self._anchor: Extrapolated | None = None  # the newest joint sample's state, and its loads
        self._anchor_t: int | None = None
        self._anchor_loads = np.zeros(6)

    def judge(self, t_ns: int, raw, newest: Sample, previous: Sample) -> tuple[Detection, np.ndarray]:
        """One frame at host time ``t_ns``: ``raw`` (6,) the reading; the joint state there extrapolated from the
        ``newest`` joint sample and the one before it (``previous``), each (time ns, q, qd). Returns the
        detection and the external wrench (6,) it judged.

        The arm's loads are computed once per joint sample, at the sample's own state (q0, qd0 and the samples'
        acceleration a), and carried to the frame's time through the model's sensitivities (q moves by
        qd0 h + a h^2/2, qd by a h, qdd not at all): a frame costs a few products instead of an inverse dynamics
        (at 7 kHz, 14 frames per joint sample); the linearization's error over a few ms is far below the rows'."""
        comp = self.compensator
        anchor = self._anchor_at(newest, previous)
        sens = self._sens
        h = (t_ns - newest[0]) * 1e-9
        loads = self._anchor_loads + sens.q @ (anchor.qd * h + anchor.qdd * (0.5 * h * h)) + sens.qd @ (anchor.qdd * h)
        external = comp.contact_wrench(comp.unbiased(raw), loads if comp.gain is None else comp.gain @ loads)
        rows = extrapolation_rows(sens, self.spread.spread, h, (newest[0] - previous[0]) * 1e-9)
        identified = self.pipeline.motion.identified_error
        if identified is not None:  # the rows the pipeline last computed (asking anew would move its cache)
            rows = np.vstack([rows, identified._rows])
        return self.detector.update(t_ns, external, rows), external

    def _anchor_at(self, newest: Sample, previous: Sample) -> Extrapolated:
        """The state at the newest joint sample (its acceleration the two samples'), its loads and, every
        ``SENSITIVITY_REFRESH_NS``, the model's sensitivities there: computed once per joint sample."""
        if self._anchor is None or newest[0] != self._anchor_t:
            anchor = extrapolate(newest[0], newest, previous)
            t0 = newest[0]
            if self._sens is None or abs(t0 - self._sens_t) >= SENSITIVITY_REFRESH_NS:
                self._sens = wrench_sensitivities(self.model, self.compensator.level, anchor.q, anchor.qd,
                                                  anchor.qdd)
                self._sens_t = t0
            self._anchor_loads = self.model.arm_loads(anchor.q, anchor.qd, anchor.qdd, self.compensator.level)[0]
            self._anchor, self._anchor_t = anchor, t0
        return self._anchor

    def reset(self) -> None:
        """A stream was lost: the provisional detector starts afresh, as the pipeline's does."""
        self.detector.reset()


class ProvisionalLedger:
    """Provisional onsets waiting for the confirmed judgement (module docstring). Times are host ns."""

    def __init__(self, window_ns: int = CONFIRM_WINDOW_NS) -> None:
        self.window_ns = window_ns
        self._open: deque[int] = deque()
        self._contact_until: int | None = None  # the newest confirmed frame in contact
        self._last_onset: int | None = None  # the newest provisional onset (confirmed or not)

    @property
    def waiting(self) -> int:
        return len(self._open)

    def provisional(self, t_onset_ns: int) -> bool:
        """A provisional onset at ``t_onset_ns``; True when the pipeline was already in contact within the window
        (confirmed at once), else it waits."""
        self._last_onset = t_onset_ns
        if self._contact_until is not None and abs(t_onset_ns - self._contact_until) <= self.window_ns:
            return True
        self._open.append(t_onset_ns)
        return False

    def judged(self, t_ns: int, in_contact: bool) -> tuple[int, list[int]]:
        """The pipeline judged a frame at ``t_ns``: (how many waiting onsets it confirms, the onsets it leaves
        unconfirmed: those whose window it has passed)."""
        unconfirmed = []
        while self._open and t_ns - self._open[0] > self.window_ns:
            unconfirmed.append(self._open.popleft())
        confirmed = 0
        if in_contact:
            self._contact_until = t_ns
            while self._open and self._open[0] - t_ns <= self.window_ns:  # older than the window: gone above
                self._open.popleft()
                confirmed += 1
        return confirmed, unconfirmed

    def had_provisional(self, t_onset_ns: int) -> bool:
        """Whether a provisional onset came within the window of a confirmed onset at ``t_onset_ns``."""
        return self._last_onset is not None and abs(t_onset_ns - self._last_onset) <= self.window_ns
