"""One static pose's data: the raw samples of a collection window, and the mean reading while the arm
held still, with how still it was."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PoseSample:
    """The F/T samples taken at one pose, reduced to what the fit needs.

    ``wrench``: mean reading (sensor frame, scene convention); ``wrench_std``: per-axis sample standard
    deviation; ``n``: samples averaged; ``q``: mean joint angles (rad); ``qd_max``: largest joint speed
    seen while sampling (rad/s); ``t``: mid-time of the sampling (s, any clock shared by the poses).
    """

    q: np.ndarray
    wrench: np.ndarray
    wrench_std: np.ndarray
    n: int
    qd_max: float = 0.0
    t: float = 0.0

    @classmethod
    def from_arrays(cls, q: np.ndarray, wrenches: np.ndarray, qd: np.ndarray | None = None,
                    t: np.ndarray | float = 0.0) -> PoseSample:
        """From raw arrays: ``q`` (k, n) or (n,), ``wrenches`` (N, 6), ``qd`` (k, n), ``t`` sample times."""
        w = np.asarray(wrenches, dtype=float).reshape(-1, 6)
        if len(w) < 2:
            raise ValueError("a pose needs at least 2 F/T samples")
        q = np.atleast_2d(np.asarray(q, dtype=float))
        qd_max = 0.0 if qd is None or np.size(qd) == 0 else float(np.abs(np.asarray(qd, dtype=float)).max())
        t_mid = float(np.mean(t))
        return cls(q=q.mean(axis=0), wrench=w.mean(axis=0), wrench_std=w.std(axis=0, ddof=1), n=len(w),
                   qd_max=qd_max, t=t_mid)


@dataclass
class Window:
    """Raw samples over one collection window."""

    wrench: np.ndarray  # (N, 6)
    t: np.ndarray  # (N,) host s
    q: np.ndarray  # (k, n)
    qd: np.ndarray  # (k, n)
    sim_t: tuple[float, float] | None = None  # world time at the start and end (sim only)
    duration: float = 0.0

    def gap(self, rate_hz: float) -> str | None:
        """Why the window is not a complete record (a device dropped out and is reconnecting), or None."""
        expected = self.duration * rate_hz
        if len(self.q) == 0 or len(self.wrench) < 0.8 * expected:
            return (f"data interrupted ({len(self.wrench)} of ~{expected:.0f} F/T frames, {len(self.q)} joint "
                    "frames): waiting for the devices")
        return None

    def sample(self) -> PoseSample:
        return PoseSample.from_arrays(self.q, self.wrench, self.qd, self.t)
