"""Which probes a sensing can see at all, judged from the world's truth and the detector's own threshold,
so that a bench's detection rate can be told apart into the method's misses and the physics' (issue 37).

The criterion. The detector tests one vector z per frame (the momentum observer's residual r (n,) N m for
joint signals; [r, w] with a flange F/T sensor's contact wrench w; the compensated wrench for a base F/T
sensor). The criterion's threshold is an ideal detector's that knows which link is touched: the chi-square
quantile at the detector's per-sample false-alarm probability ``p_false`` with as many degrees of freedom
as components the contact can load (``link_dof``: the joints that move the link, the wrench's 6 where the
F/T sensor carries the link) -- the same whichever test the pipeline runs. The **noise floor** is z's
measured spread in the same world's free run (same draw, same sweep, no contact), per component: its root
mean square about zero, what the test faces from noise, friction and model error together while the arm
moves; a joint's component by the speed of that joint (bins of |qd_j|, ``SPEED_EDGES``), since its
friction's share is set by it (measured, ur10e typical, shoulder-lift joint: 0.34 N m above 0.1 rad/s, 2.5
N m at 0.01-0.03, 10 N m below 0.01 rad/s, where static friction holds anything within +-f_c). A probe's
**true vector** is what its contact alone puts into z: ``J^T f`` (the world's force at the world's point,
the Jacobian at the world's pose) for the joints; the contact's wrench at the F/T sensor (none where the
sensor does not see the touched link). A probe is **detectable** when, within 20 ms of its start (the
acceptance's window), some frame's ``sum_k (z_true,k / floor_k)^2`` (each joint's floor at that frame's
speed) exceeds that threshold: a contact that stands out of the measured floor as far as the ideal test
asks. Below it no test on these signals at this false-alarm rate could call it reliably; above it a miss is
the method's (its covariance, its observer's lag, its test). Nothing here is tuned to the result: the floor
is measured, the threshold is the chi-square's at the detector's false-alarm probability, the window is the
acceptance's. The floor is diagonal (the components' correlations left out).

What the floor holds besides physics: the identified model's own error (a better identification lowers
it, and more probes become detectable); the criterion measures the detector against the residual it is
given, not the residual against the sensors.
"""
from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from ftc_hw.detection.joint import chi2_isf
from ftc_hw.model import ArmModel, Contact
from ftc_hw.pipeline.joint import sensor_sees
from ftc_hw.scene import Scene

WINDOW_S = 0.020  # from the probe's start: the acceptance's "within 20 ms"
SPEED_EDGES = np.array([0.005, 0.01, 0.02, 0.05, 0.1, 0.2])  # rad/s: a joint's floor by |qd| in these bins
MIN_FRAMES = 50  # a bin's floor from fewer frames is not trusted: the component's over every bin instead


class Floor:
    """The root mean square about zero of the tested vectors ``add``-ed (the free run's), per component:
    the first ``n_joints`` components (a joint each) by their joint's speed bin, the others in one."""

    def __init__(self, size: int, n_joints: int) -> None:
        self.n_joints = n_joints
        self._sum = np.zeros((size, len(SPEED_EDGES) + 1))
        self._count = np.zeros((size, len(SPEED_EDGES) + 1), dtype=int)
        self.frames = 0

    def _bins(self, qd: np.ndarray) -> np.ndarray:
        b = np.zeros(self._sum.shape[0], dtype=int)
        b[:self.n_joints] = np.searchsorted(SPEED_EDGES, np.abs(np.asarray(qd, dtype=float)[:self.n_joints]))
        return b

    def add(self, z: np.ndarray, qd: np.ndarray) -> None:
        z = np.asarray(z, dtype=float)
        if not (np.isfinite(z).all() and np.isfinite(qd).all()):
            return
        rows = np.arange(z.size)
        b = self._bins(qd)
        self._sum[rows, b] += z * z
        self._count[rows, b] += 1
        self.frames += 1

    def std(self, qd: np.ndarray) -> np.ndarray:
        """(size,) each component's floor at joint speeds qd: its bin's, or over every bin where its bin
        holds fewer than ``MIN_FRAMES``; inf where the free run had none."""
        rows = np.arange(self._sum.shape[0])
        b = self._bins(qd)
        n, total = self._count[rows, b], self._sum[rows, b]
        every_n, every = self._count.sum(axis=1), self._sum.sum(axis=1)
        use_all = n < MIN_FRAMES
        n = np.where(use_all, every_n, n)
        total = np.where(use_all, every, total)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(n > 0, np.sqrt(total / np.maximum(n, 1)), np.inf)

    def table(self) -> list[list[float | None]]:
        """Per component, the floor in each speed bin (None: fewer than ``MIN_FRAMES`` there)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            rms = np.sqrt(self._sum / np.maximum(self._count, 1))
        return [[float(v) if c >= MIN_FRAMES else None for v, c in zip(row, counts, strict=True)]
                for row, counts in zip(rms, self._count, strict=True)]


class TruthVector:
    """What a frame's contacts alone put into the tested vector (see the module's notes), at the world's
    pose: ``joints`` the external joint torques J^T f (n,), ``ft`` the contact wrench at the scene's F/T
    sensor (6,, its frame; None: no F/T part). The order is the detector's: joints first, then the wrench."""

    def __init__(self, scene: Scene, *, joints: bool, ft: bool) -> None:
        self.model = ArmModel(scene)  # its own: the pipeline's model keeps its poses cached
        self.joints, self.ft = joints, ft

    def __call__(self, q: np.ndarray, contacts: Iterable) -> np.ndarray:
        cs = [Contact(c.link, np.asarray(c.point, dtype=float), np.asarray(c.force, dtype=float)) for c in contacts]
        parts = []
        if self.joints:
            tau = np.zeros(self.model.n_joints)
            for c in cs:
                tau += self.model.jacobian(q, c.link, c.point).T @ c.force
            parts.append(tau)
        if self.ft:
            parts.append(self.model.predicted_wrench(q, level="bias", contacts=cs))
        return np.concatenate(parts)


def d2_against(z_true: np.ndarray, floor_std: np.ndarray) -> float:
    """sum_k (z_true,k / floor_k)^2."""
    return float(np.sum((np.asarray(z_true, dtype=float) / floor_std) ** 2))


def probe_d2(truth: list[tuple[float, np.ndarray, np.ndarray]], floor: Floor, t_start: float) -> float:
    """The largest d2 of the true vectors ``truth`` (t s, z_true, qd rad/s) of a probe starting at ``t_start``
    s within ``[t_start, t_start + WINDOW_S]``, each against the floor at its frame's joint speeds; 0 when no
    frame falls there."""
    inside = [(z, qd) for t, z, qd in truth if t_start <= t <= t_start + WINDOW_S + 1e-9]
    return max((d2_against(z, floor.std(qd)) for z, qd in inside), default=0.0)


def link_threshold(model: ArmModel, link: str, *, joints: bool, ft: bool, p_false: float) -> float:
    """The ideal test's threshold for a contact on ``link``: the chi-square quantile at ``p_false`` with
    ``link_dof`` degrees of freedom (inf where the contact loads nothing tested)."""
    k = link_dof(model, link, joints=joints, ft=ft)
    return chi2_isf(p_false, k) if k else float("inf")


def link_dof(model: ArmModel, link: str, *, joints: bool, ft: bool) -> int:
    """How many tested components a contact on ``link`` can load: the joints that move it (``joints``),
    and the F/T sensor's 6 where the sensor carries the link (``ft``)."""
    return (int(model.moving_joints(link).sum()) if joints else 0) + (6 if ft and sensor_sees(model, link) else 0)
