"""A contact's class, live: transient or quasi-static (clamped), accidental impact or intended guidance.

Collision handling's fourth phase after detection, isolation and identification (Haddadin, De Luca &
Albu-Schaeffer, "Robot collisions: a survey on detection, isolation, and identification", IEEE T-RO
33(6), 2017): what kind of contact it was. Three kinds, one small Bayesian model over physical features
of the contact so far (naive Bayes: each feature's likelihood under each kind, their product, equal
priors):

- ``impact``: accidental and transient: the arm moved into something that could recoil, released within
  about 0.5 s (ISO/TS 15066:2016's transient contact);
- ``clamping``: accidental and quasi-static: the force persists (or grows) while the arm does not move
  away (the standard's quasi-static contact: a body part clamped);
- ``guidance``: a person leading the arm: the force rises slowly (low jerk) and the arm moves along it.

Features (each frame in contact: the contact force's magnitude ``|F|`` and the power ``P = F . v`` it
puts into the arm, ``v`` the contact point's velocity; ``P / |F|`` is the point's speed along the force,
positive when the arm yields to it):

- ``held_s``: from the onset to the last frame whose force was at least a quarter of the peak; ``released``:
  the contact closed or its force fell under a quarter of its peak;
- ``rise_s``: from the onset to the force's peak so far (a stand-in for the jerk Golz, Osendorfer &
  Haddadin used to tell collisions from interaction, ICRA 2015 "Using tactile sensation for learning
  contact knowledge: Discriminate collision from physical interaction": a contact that peaks within
  0.15 s rose at tens of N/s per N);
- ``v_onset``: the point's mean speed along the force over the first 60 ms (negative: the arm was moving
  into the contact, as it does in an impact);
- ``v_held``: its mean, weighted by the force, over the frames from 0.25 s on whose force held (positive:
  the arm yields, as a guided arm does; about zero: the arm is stopped against it, as a clamped one is);
  ``v_recent``, the same over the last 0.2 s, is reported beside it.

Each likelihood is a logistic step at a physical threshold (its softness the features' noise; ESTIMATEs,
argued in docs/contacts.md). ``p_quasi_static`` is the clamping kind's probability, ``p_guidance`` the
guidance kind's; a value is named when its probability is at least ``CONFIDENT``, else ``unknown``.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

TRANSIENT_S = 0.5  # ISO/TS 15066: a transient contact is released within about 0.5 s
TRANSIENT_SOFT_S = 0.06
RISE_S = 0.25  # s from onset to peak: a faster rise is an impact's, a slower a hand's (ESTIMATE: docs/contacts.md)
RISE_SOFT_S = 0.05
YIELD_MPS = 0.02  # m/s along the force: faster, the arm yields (a guiding hand moves it at 0.05-0.15 m/s)
YIELD_SOFT_MPS = 0.004
INTO_MPS = -0.03  # m/s along the force at onset: slower (more negative), the arm was moving into the contact
INTO_SOFT_MPS = 0.01
ONSET_WINDOW_S = 0.06
RECENT_WINDOW_S = 0.2
HELD_SHARE = 0.25  # of the peak: the contact holds while its force is above this
JUDGE_MOTION_S = 0.25  # the arm's yielding is judged from this age on (the hand's force has built up)
CONFIDENT = 0.8
KINDS = ("impact", "clamping", "guidance")


@dataclass(frozen=True)
class ContactClass:
    """The class of a contact so far: its kinds' probabilities, the axes' names and the features."""

    p_impact: float
    p_clamping: float
    p_guidance: float
    features: dict[str, float]

    @property
    def p_quasi_static(self) -> float:
        return self.p_clamping

    @property
    def contact_class(self) -> str:
        return _named(self.p_clamping, "quasi_static", "transient")

    @property
    def intent(self) -> str:
        return _named(self.p_guidance, "guidance", "impact")

    def event_fields(self) -> dict[str, object]:
        """The ContactEvent fields it fills."""
        return {"contact_class": self.contact_class, "p_quasi_static": self.p_quasi_static, "intent": self.intent,
                "p_guidance": self.p_guidance, "class_features": self.features}


def _named(p: float, yes: str, no: str) -> str:
    return yes if p >= CONFIDENT else no if 1.0 - p >= CONFIDENT else "unknown"


def _sig(x: float) -> float:
    return 1.0 / (1.0 + math.exp(-max(min(x, 50.0), -50.0)))


class ContactClassifier:
    """One contact at a time: :meth:`begin` at its onset, :meth:`add` each frame in it, :meth:`result`
    whenever an event goes out (``released`` at its offset). O(1) per frame (running sums over windows)."""

    def __init__(self) -> None:
        self.begin(0)

    def begin(self, t_ns: int) -> None:
        self.t0 = t_ns
        self.peak = 0.0
        self.t_peak = t_ns
        self.t_held = t_ns
        self.onset_sum = self.onset_n = 0.0
        self.held_power = self.held_force = 0.0  # sums of F . v and |F| over the held frames past JUDGE_MOTION_S
        self._recent: deque[tuple[int, float, float]] = deque()  # (t_ns, |F|, speed along F: nan unknown)
        self.last_t = t_ns

    def add(self, t_ns: int, force: float, power: float | None) -> None:
        """A frame in contact: ``force`` (N) the contact force's magnitude, ``power`` (W) ``F . v`` (None:
        not known this frame)."""
        if not math.isfinite(force):
            return
        self.last_t = t_ns
        if force > self.peak:
            self.peak, self.t_peak = force, t_ns
        held = force >= HELD_SHARE * self.peak
        if held:
            self.t_held = t_ns
        known = power is not None and math.isfinite(power) and force > 0.0
        v = power / force if known else math.nan
        self._recent.append((t_ns, force, v))
        cut = t_ns - int(RECENT_WINDOW_S * 1e9)
        while self._recent[0][0] < cut:
            self._recent.popleft()
        if not known:
            return
        age = (t_ns - self.t0) * 1e-9
        if age <= ONSET_WINDOW_S:
            self.onset_sum += v
            self.onset_n += 1
        elif held and age >= JUDGE_MOTION_S:
            self.held_power += power
            self.held_force += force

    def features(self, released: bool) -> dict[str, float]:
        f_recent = sum(f for _, f, _ in self._recent) / len(self._recent) if self._recent else 0.0
        recent = [v for _, f, v in self._recent if f >= HELD_SHARE * self.peak and not math.isnan(v)]
        out = {"age_s": (self.last_t - self.t0) * 1e-9, "held_s": (self.t_held - self.t0) * 1e-9,
               "rise_s": (self.t_peak - self.t0) * 1e-9, "peak_n": self.peak,
               "released": float(released or f_recent < HELD_SHARE * self.peak)}
        if self.onset_n:
            out["v_onset_mps"] = self.onset_sum / self.onset_n
        if recent:
            out["v_recent_mps"] = sum(recent) / len(recent)
        if self.held_force > 0.0:
            out["v_held_mps"] = self.held_power / self.held_force
        return out

    def result(self, released: bool = False) -> ContactClass:
        """The class so far (``released``: the contact has closed)."""
        x = self.features(released)
        like = {k: 1.0 for k in KINDS}
        held, gone = x["held_s"], x["released"] > 0.5
        like["impact"] *= _sig((TRANSIENT_S - held) / TRANSIENT_SOFT_S)  # an impact does not last
        if gone:  # released: the others last longer than the transient window
            stay = _sig((held - TRANSIENT_S) / TRANSIENT_SOFT_S)
            like["clamping"] *= stay
            like["guidance"] *= stay
        if x["age_s"] >= RISE_S + 2 * RISE_SOFT_S or gone:
            like["impact"] *= _sig((RISE_S - x["rise_s"]) / RISE_SOFT_S)
            like["guidance"] *= _sig((x["rise_s"] - RISE_S) / RISE_SOFT_S)
        if "v_onset_mps" in x:
            like["impact"] *= _sig((INTO_MPS - x["v_onset_mps"]) / INTO_SOFT_MPS)
            like["guidance"] *= _sig((x["v_onset_mps"] - INTO_MPS) / INTO_SOFT_MPS)
        if "v_held_mps" in x:
            v = x["v_held_mps"]
            like["guidance"] *= _sig((v - YIELD_MPS) / YIELD_SOFT_MPS)
            like["clamping"] *= _sig((YIELD_MPS - v) / YIELD_SOFT_MPS)
        total = sum(like.values())
        p = {k: v / total for k, v in like.items()} if total > 0 else {k: 1 / 3 for k in KINDS}
        return ContactClass(p["impact"], p["clamping"], p["guidance"], x)
