"""Taking one pose's sample: wait until the arm is still, sample, check it was still throughout.

A sample taken in motion or contact is rejected with the stillness gate's reason and taken again
(up to ``attempts`` times); the caller decides what to do when a pose never settles.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from ftc_hw.scene import Scene

from .samples import PoseSample, Window
from .stillness import StillnessGate

SETTLE_WINDOW_S = 0.3


class WindowSource(Protocol):
    """What a pose's sampling needs of the devices (the wizard's device session is one)."""

    scene: Scene

    def collect(self, duration: float, progress: Callable[[float], None] | None = None) -> Window: ...

    def joint_state(self) -> tuple[np.ndarray, np.ndarray]: ...


@dataclass
class PoseResult:
    sample: PoseSample | None
    rejected: list[str] = field(default_factory=list)  # why earlier attempts were refused
    sim_t: tuple[float, float] | None = None


def wait_still(session: WindowSource, gate: StillnessGate, timeout: float,
               status: Callable[[str, float], None] | None = None) -> str | None:
    """Block until a settle window is still; None when it is, else the last reason at the timeout."""
    t0 = time.monotonic()
    reason = "no data"
    while time.monotonic() - t0 < timeout:
        w = session.collect(SETTLE_WINDOW_S)
        gap = w.gap(session.scene.sensor.rate_hz)
        report = None if gap else gate.check(w.wrench, w.q, w.qd)
        if report is not None and report.still:
            return None
        reason = gap or report.reason
        if status is not None:
            status(reason, (time.monotonic() - t0) / timeout)
    return reason


def take_sample(session: WindowSource, gate: StillnessGate, duration: float, *, attempts: int = 4,
                settle_timeout: float = 15.0, progress: Callable[[str, float], None] | None = None) -> PoseResult:
    out = PoseResult(None)
    for _ in range(attempts):
        reason = wait_still(session, gate, settle_timeout, progress)
        if reason is not None:
            out.rejected.append(f"did not settle within {settle_timeout:g} s: {reason}")
            continue
        w = session.collect(duration, None if progress is None else (lambda s: progress("sampling", s)))
        gap = w.gap(session.scene.sensor.rate_hz)
        if gap:
            out.rejected.append(f"sample rejected: {gap}")
            continue
        report = gate.check(w.wrench, w.q, w.qd)
        if not report.still:
            out.rejected.append(f"sample rejected: {report.reason}")
            continue
        out.sample = w.sample()
        out.sim_t = w.sim_t
        return out
    return out


def pose_error(session: WindowSource, q_goal: np.ndarray) -> np.ndarray:
    q, _ = session.joint_state()
    return q - np.asarray(q_goal, dtype=float)
