"""Which probes a sensing can see at all, judged from the world's truth and the detector's own threshold,
so that a bench's detection rate can be told apart into the method's misses and the physics' (issue 37).

The criterion. The detector tests one vector z per frame (the momentum observer's residual r (n,) N m for
joint signals; [r, w] with a flange F/T sensor's contact wrench w; the compensated wrench for a base F/T
sensor) against a chi-square threshold ``on`` (its onset quantile at its per-sample false-alarm
probability, with its own degrees of freedom). The **noise floor** is z's measured spread in the same
world's free run (same draw, same sweep, no contact): its second moment about zero, ``S = mean(z z^T)``,
what the test faces from noise, friction and model error together while the arm moves. A probe's **true
vector** is what its contact alone puts into z: ``J^T f`` (the world's force at the world's point, the
Jacobian at the world's pose) for the joints; the contact's wrench at the F/T sensor (none where the
sensor does not see the touched link). A probe is **detectable** when, within 20 ms of its start (the
acceptance's window), some frame's ``z_true^T S^-1 z_true`` exceeds ``on``: a contact that
stands out of the measured floor as far as the detector's threshold asks. Below it no test on these
signals with this false-alarm rate could call it reliably; above it a miss is the method's (its
covariance, its observer's lag, its test). Nothing here is tuned to the result: S is measured, ``on`` is
the detector's, the window is the acceptance's.

What the floor holds besides physics: the identified model's own error (a better identification lowers
it, and more probes become detectable); the criterion measures the detector against the residual it is
given, not the residual against the sensors.
"""
from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from ftc_hw.model import ArmModel, Contact
from ftc_hw.scene import Scene

WINDOW_S = 0.020  # from the probe's start: the acceptance's "within 20 ms"


class Floor:
    """The second moment about zero of the vectors ``add``-ed (the free run's tested vector)."""

    def __init__(self) -> None:
        self._sum: np.ndarray | None = None
        self.frames = 0

    def add(self, z: np.ndarray) -> None:
        z = np.asarray(z, dtype=float)
        if not np.isfinite(z).all():
            return
        outer = np.outer(z, z)
        self._sum = outer if self._sum is None else self._sum + outer
        self.frames += 1

    def cov(self) -> np.ndarray | None:
        """S (m, m), or None before any frame."""
        return None if self._sum is None else self._sum / self.frames


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


def d2_against(z_true: np.ndarray, floor: np.ndarray) -> float:
    """z_true^T S^-1 z_true (the pseudo-inverse where S is singular: a direction the free run never
    moved in is one no frame was tested along)."""
    return float(z_true @ np.linalg.pinv(floor) @ z_true)


def probe_d2(truth: list[tuple[float, np.ndarray]], floor: np.ndarray, t_start: float) -> float:
    """The largest d2 of the true vectors ``truth`` (t s, z_true) of a probe starting at ``t_start`` s within
    ``[t_start, t_start + WINDOW_S]``; 0 when no frame falls there."""
    inside = [z for t, z in truth if t_start <= t <= t_start + WINDOW_S + 1e-9]
    return max((d2_against(z, floor) for z in inside), default=0.0)
