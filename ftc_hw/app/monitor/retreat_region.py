"""Where on the arm a touched point may be, for the retreat: the onset's estimate is centimetres off at times
(its first frames' force is a few newtons; on dxl-arm at times on the other finger, 7 cm away; on ur5e at times
on the next link), so the retreat moves back every point of the arm's surface the contact may be at, not the
estimate alone.

That region is the event's 95 % ellipsoid (``point_std`` per base axis, each at least ``floor_m``) and a tube
around the event's line of action (its other crossings of the surface), within ``reach_m`` of the estimate, on
the touchable surfaces of every link a retreat can move, sampled uniformly by area once per model. An
estimate further off than ``reach_m`` (ur5e, some onsets: on the forearm, 20-27 cm from the wrist it touched)
is not covered.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ftc_hw.model import ArmModel
from ftc_hw.model.sampling import _area, sample_local

CHI2_3DOF_95 = 7.815  # the chi-square distribution's 95 % quantile at 3 degrees of freedom (any statistics table)
# ESTIMATE: one sample per 30 mm^2 (about 5.5 mm apart): a link turning 0.1 rad moves neighbours within 0.6 mm
# of each other, so the least displacement over the samples is within ~0.6 mm of the surface's
AREA_PER_SAMPLE_M2 = 30e-6
MAX_SAMPLES_PER_PRIMITIVE = 1500  # bounds the planning time on a large link (ur5e's upper arm: ~2400 at the spacing)


def frozen_joints(model: ArmModel) -> np.ndarray:
    """The joints (bool per scene joint) the retreat leaves where they are: a coupling's (a gripper)."""
    coupled = {c.joint for c in model.scene.robot.couplings}
    return np.array([j in coupled for j in model.scene.robot.joints])


@dataclass(frozen=True)
class Region:
    """Points of the arm: ``points`` (k, 3, m) each in the frame of its link ``links[link_of[i]]``; the
    estimate first."""

    links: tuple[str, ...]
    link_of: np.ndarray
    points: np.ndarray

    @classmethod
    def of_point(cls, link: str, point_link: np.ndarray) -> Region:
        return cls((link,), np.zeros(1, dtype=int), np.asarray(point_link, dtype=float).reshape(1, 3))

    def __len__(self) -> int:
        return len(self.points)

    def take(self, idx: np.ndarray) -> Region:
        return Region(self.links, self.link_of[idx], self.points[idx])

    def at(self, model: ArmModel, q: np.ndarray) -> np.ndarray:
        """The points in the base frame at q (k, 3): one kinematics pass, the region's bodies' poses only."""
        xpos, xquat = model.body_poses(q)
        out = np.empty_like(self.points)
        for link, mine in self._by_link:
            bid = model.model.body(link).id
            out[mine] = self.points[mine] @ _rotation(xquat[bid]).T + xpos[bid]
        return out

    @cached_property
    def _by_link(self) -> list[tuple[str, np.ndarray]]:
        return [(link, np.flatnonzero(self.link_of == i)) for i, link in enumerate(self.links)]


def _rotation(quat: np.ndarray) -> np.ndarray:
    """The rotation matrix of a unit quaternion (w, x, y, z)."""
    w, x, y, z = quat
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


class SurfaceSamples:
    """Points uniform by area on each touchable link's primitives, in the link's frame (fixed seed: a
    retreat's plan is repeatable), of the links a retreat can move. ``region`` picks those a contact may be at."""

    def __init__(self, model: ArmModel, seed: int = 0) -> None:
        self.model = model
        rng = np.random.default_rng(seed)
        frozen = frozen_joints(model)
        per_link: dict[str, list[np.ndarray]] = {}
        for s in model.surfaces:
            if not (model.moving_joints(s.link) & ~frozen).any():
                continue  # the base, or a link only a gripper's coupling moves: no retreat moves it
            n = min(MAX_SAMPLES_PER_PRIMITIVE, max(8, round(_area(s.kind, s.size) / AREA_PER_SAMPLE_M2)))
            local = np.array([sample_local(s.kind, s.size, rng)[0] for _ in range(n)])
            per_link.setdefault(s.link, []).append(local @ s.link_T_geom[:3, :3].T + s.link_T_geom[:3, 3])
        self.points = {link: np.concatenate(chunks) for link, chunks in per_link.items()}

    def region(self, q: np.ndarray, *, link: str, point: np.ndarray, point_std: np.ndarray, floor_m: float,
               reach_m: float = np.inf, force=None, tube_m: float = 0.0) -> Region:
        """Where the contact estimated at ``point`` (base, m) on ``link`` with ``point_std`` (3, m, 1 sigma per
        base axis) may be, at q (rad): the estimate first, then the samples within ``reach_m`` of the
        estimate that are inside the 95 % ellipsoid with each sigma at least ``floor_m``, or within ``tube_m``
        of the line through the estimate along ``force`` (3, N: its line of action, where the other
        crossings of the surface lie, one of which the localization picked)."""
        poses = self.model.kinematics(q)
        point = np.asarray(point, dtype=float)
        sigma = np.maximum(np.nan_to_num(np.asarray(point_std, dtype=float), nan=np.inf), floor_m)
        f = np.zeros(3) if force is None else np.nan_to_num(np.asarray(force, dtype=float))
        line = f / np.linalg.norm(f) if np.linalg.norm(f) > 0.0 else None
        t = poses[link]
        links, link_of, pts = [link], [np.zeros(1, dtype=int)], [(t[:3, :3].T @ (point - t[:3, 3]))[None]]
        for other, local in self.points.items():
            t = poses[other]
            off = local @ t[:3, :3].T + t[:3, 3] - point
            inside = np.sum((off / sigma) ** 2, axis=1) <= CHI2_3DOF_95
            if line is not None and tube_m > 0.0:
                across = off - np.outer(off @ line, line)
                inside |= np.sum(across * across, axis=1) <= tube_m**2
            inside &= np.sum(off * off, axis=1) <= reach_m**2
            if not inside.any():
                continue
            if other not in links:
                links.append(other)
            link_of.append(np.full(int(inside.sum()), links.index(other)))
            pts.append(local[inside])
        return Region(tuple(links), np.concatenate(link_of), np.concatenate(pts))
