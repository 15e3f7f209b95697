"""Pose planning: N static poses inside the joint limits, free of self-collision and of the mounting
surface, that maximise the information about the calibration parameters (D-optimal design: greedy
selection, then Fedorov exchange, on ``log det`` of the summed information matrices), and the standard
errors they should give before anyone moves.
"""
from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from ftc_hw.model import JointMap, load_spec
from ftc_hw.scene import Scene

from .arm_gravity import joint_limits
from .identify import Identifier

LIMIT_MARGIN = 0.1  # rad kept from each joint limit
COLLISION_MARGIN = 0.01  # m between non-adjacent links, and from the mounting surface


class CollisionChecker:
    """MuJoCo contacts between the arm's own geoms (every geom, parent-child pairs excluded) and with
    the plane through the base origin perpendicular to gravity (the table the arm stands on)."""

    def __init__(self, scene: Scene, margin: float = COLLISION_MARGIN) -> None:
        spec = load_spec(scene)
        for g in spec.geoms:
            g.contype, g.conaffinity, g.margin = 1, 1, margin
        for b in spec.bodies:
            parent = b.parent
            if parent is not None and parent.name and b.name:
                spec.add_exclude(bodyname1=parent.name, bodyname2=b.name)
        up = -np.asarray(scene.gravity, dtype=float)
        up /= np.linalg.norm(up)
        quat = np.zeros(4)
        mujoco.mju_quatZ2Vec(quat, up)
        spec.worldbody.add_geom(name="ftc_mounting_surface", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[5, 5, 0.1],
                                quat=quat, contype=1, conaffinity=1, margin=margin)
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        self.margin = margin
        self._joints = JointMap(self.model, scene)

    def collides(self, q) -> list[tuple[str, str]]:
        """The geom pairs closer than the margin at q (empty: the pose is clear)."""
        m, d = self.model, self.data
        self._joints.set_qpos(np.asarray(q, dtype=float), d.qpos)
        mujoco.mj_kinematics(m, d)
        mujoco.mj_collision(m, d)
        out = []
        for c in d.contact[:d.ncon]:
            if c.dist < self.margin:
                out.append((m.geom(c.geom1).name or f"geom{c.geom1}", m.geom(c.geom2).name or f"geom{c.geom2}"))
        return out


@dataclass
class Plan:
    q: np.ndarray  # (N, n) poses in visiting order
    names: list[str]
    cov: np.ndarray  # expected covariance of the parameters
    expected_std: dict[str, float | list[float]]
    log_det: float
    samples_per_pose: int
    expected_mass: float


def candidate_poses(scene: Scene, identifier: Identifier, count: int, rng: np.random.Generator,
                    checker: CollisionChecker | None = None) -> np.ndarray:
    """Random collision-free poses inside the joint limits (less a margin); see ``joint_limits``."""
    lo, hi = joint_limits(identifier.gm)
    # a full turn changes nothing for gravity: keep unlimited and multi-turn joints within one turn
    lo, hi = np.maximum(lo, -np.pi), np.minimum(hi, np.pi)
    span = hi - lo
    lo_m = lo + np.minimum(LIMIT_MARGIN, 0.1 * span)
    hi_m = hi - np.minimum(LIMIT_MARGIN, 0.1 * span)
    checker = checker or CollisionChecker(scene)
    out: list[np.ndarray] = []
    tries = 0
    while len(out) < count and tries < 50 * count:
        tries += 1
        q = rng.uniform(lo_m, hi_m)
        if not checker.collides(q):
            out.append(q)
    if not out:
        raise RuntimeError(f"no collision-free pose found for scene {scene.name!r} in {tries} tries")
    return np.array(out)


def pose_information(identifier: Identifier, q: np.ndarray, n_samples: int, p0: np.ndarray) -> np.ndarray:
    g = identifier.gm.at(q)
    j = identifier.jacobian(g, p0)
    cov = identifier.pose_cov(g, p0, n_samples)
    return j.T @ np.linalg.solve(cov, j)


def nominal_parameters(identifier: Identifier, expected_mass: float) -> np.ndarray:
    p0 = np.zeros(len(identifier.names))
    p0[6] = expected_mass
    return p0


def d_optimal(infos: np.ndarray, n: int, max_passes: int = 5) -> list[int]:
    """Indices of n candidates maximising log det(sum of their information): greedy, then exchange."""
    k = infos.shape[1]
    reg = 1e-9 * np.trace(infos.mean(axis=0)) / k * np.eye(k)
    chosen: list[int] = []
    total = reg.copy()
    for _ in range(n):
        _, ld = np.linalg.slogdet(total[None] + infos)
        ld[chosen] = -np.inf
        best = int(np.argmax(ld))
        chosen.append(best)
        total += infos[best]
    for _ in range(max_passes):
        improved = False
        for slot in range(n):
            base = total - infos[chosen[slot]]
            _, ld = np.linalg.slogdet(base[None] + infos)
            current = ld[chosen[slot]]
            ld[chosen] = -np.inf
            best = int(np.argmax(ld))
            if ld[best] > current + 1e-9:
                chosen[slot] = best
                total = base + infos[best]
                improved = True
        if not improved:
            break
    return chosen


def visiting_order(q: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Nearest neighbour from ``start`` (largest joint move as the distance)."""
    left = list(range(len(q)))
    order = []
    cur = np.asarray(start, dtype=float)
    while left:
        i = min(left, key=lambda j: float(np.abs(q[j] - cur).max()))
        order.append(i)
        left.remove(i)
        cur = q[i]
    return q[order]


def expected_errors(identifier: Identifier, q: np.ndarray, n_samples: int, expected_mass: float
                    ) -> tuple[np.ndarray, dict[str, float | list[float]], float]:
    p0 = nominal_parameters(identifier, expected_mass)
    info = sum(pose_information(identifier, qi, n_samples, p0) for qi in q)
    cov = np.linalg.pinv(info, rcond=1e-12, hermitian=True)
    std = np.sqrt(np.clip(np.diag(cov), 0, None))
    m = max(expected_mass, 1e-6)
    # com = h / m at h = 0: d com / d h = I / m
    out: dict[str, float | list[float]] = {
        "force_bias": std[:3].tolist(), "torque_bias": std[3:6].tolist(), "mass": float(std[6]),
        "com": (std[7:10] / m).tolist(),
    }
    for i, name in enumerate(identifier.names[10:], start=10):
        out[name] = float(std[i])
    sign, ld = np.linalg.slogdet(info)
    return cov, out, float(ld) if sign > 0 else float("-inf")


def plan_poses(scene: Scene, identifier: Identifier, n: int = 12, *, samples_per_pose: int | None = None,
               expected_mass: float = 0.5, candidates: int = 1500, seed: int = 0,
               start: np.ndarray | None = None) -> Plan:
    """D-optimal poses for this scene and fit options (``identifier``). ``samples_per_pose`` defaults
    to one second of the sensor's rate."""
    if n < 1:
        raise ValueError("plan at least one pose")
    n_s = int(samples_per_pose or round(scene.sensor.rate_hz))
    rng = np.random.default_rng(seed)
    cands = candidate_poses(scene, identifier, candidates, rng)
    p0 = nominal_parameters(identifier, expected_mass)
    infos = np.array([pose_information(identifier, q, n_s, p0) for q in cands])
    chosen = d_optimal(infos, min(n, len(cands)))
    q = visiting_order(cands[chosen], np.array(scene.robot.home) if start is None else start)
    cov, std, ld = expected_errors(identifier, q, n_s, expected_mass)
    return Plan(q=q, names=list(identifier.names), cov=cov, expected_std=std, log_det=ld, samples_per_pose=n_s,
                expected_mass=expected_mass)
