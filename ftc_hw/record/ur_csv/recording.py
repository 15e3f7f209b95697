"""A UR recording as read: the arm's joint state and what else the columns hold, in SI units, the
rows skipped by reason, the timing, and which sensing the columns allow."""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .header import FORMAT_NAMES
from .timing import Timing

# the scene sensing kinds (Scene.sensing) a column gives
SENSING_OF = {"actual_current": "currents", "ft_raw_wrench": "flange_ft"}


@dataclass(frozen=True)
class URRecording:
    """One file. Arrays have one row per kept sample, in time order; n joints (6 for UR).

    ``t`` (m,) s: the ``timestamp`` column, the controller's time (s since it started). ``q`` (m, n)
    rad, ``qd`` (m, n) rad/s, ``current`` (m, n) A (``actual_current``) or None. Where recorded:
    ``ft_raw_wrench`` (m, 6) the flange F/T sensor's wrench [fx, fy, fz, tx, ty, tz] (N, N m, flange
    frame, the payload not compensated); ``actual_tcp_force`` (m, 6) the controller's own estimate of
    the external wrench at the TCP (N, N m, base frame); ``target_current`` (m, n) A,
    ``target_moment`` (m, n) N m, ``joint_temperatures`` (m, n) degC. ``line`` (m,) each row's line in
    the file. ``rows``: data lines in the file; ``skipped``: those not kept, by reason (rows.py)."""

    path: Path
    format: str
    columns: tuple[str, ...]
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    current: np.ndarray | None
    ft_raw_wrench: np.ndarray | None
    actual_tcp_force: np.ndarray | None
    target_current: np.ndarray | None
    target_moment: np.ndarray | None
    joint_temperatures: np.ndarray | None
    line: np.ndarray
    rows: int
    skipped: Counter[str]
    timing: Timing

    @property
    def n_joints(self) -> int:
        return self.q.shape[1]

    @property
    def rate_hz(self) -> float:
        return self.timing.rate_hz

    @property
    def sensing(self) -> frozenset[str]:
        """The scene sensing kinds the columns allow: ``currents`` (actual_current), ``flange_ft``
        (ft_raw_wrench)."""
        present = {"actual_current": self.current, "ft_raw_wrench": self.ft_raw_wrench}
        return frozenset(kind for col, kind in SENSING_OF.items() if present[col] is not None)

    def skipped_by_reason(self) -> Counter[str]:
        """``skipped`` without the field names (``not_finite:actual_q`` counts as ``not_finite``)."""
        out: Counter[str] = Counter()
        for key, n in self.skipped.items():
            out[key.split(":")[0]] += n
        return out

    def summary(self) -> str:
        """One line: the file, its format, rows kept and skipped, the timing, the sensing."""
        skipped = ", ".join(f"{n} {k.replace('_', ' ')}" for k, n in sorted(self.skipped_by_reason().items()))
        kept = len(self.t)
        sensing = ", ".join(sorted(self.sensing)) or "none (joint state only)"
        extra = [name for name, v in (("actual_TCP_force", self.actual_tcp_force),
                                      ("target_current", self.target_current),
                                      ("target_moment", self.target_moment),
                                      ("joint_temperatures", self.joint_temperatures)) if v is not None]
        head = f"{self.path.name}: {FORMAT_NAMES[self.format]}, {self.n_joints} joints, {kept} of {self.rows} rows kept"
        if skipped:
            head += f" (skipped: {skipped})"
        tail = "; also " + ", ".join(extra) if extra else ""
        return f"{head}, {self.timing.describe()}; sensing: {sensing}{tail}"
