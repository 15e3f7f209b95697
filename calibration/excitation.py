"""A planned excitation for identification from free motion: each joint on a finite Fourier series
about home (the usual form for robot identification), faded in and out so that it starts and ends at
rest at home, within the joint limits, a speed limit and clear of self-collision, chosen among seeded
candidates for what it tells: the posterior information ``sum log(1 + s_k^2)`` of the fit's whitened,
prior-scaled regressor (:mod:`.free_motion`; for a scene sensed through its joints, the joint-torque
regressor of :mod:`.joint_ident`), which a direction no motion can tell does not spoil the way it spoils
a condition number.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from ftc_hw.model import ArmModel, JointMap
from ftc_hw.model.arm import SURFACE_GROUP
from ftc_hw.model.build import load_spec
from ftc_hw.scene import Scene

from .arm_gravity import joint_limits
from .free_motion import FreeMotionIdentifier
from .joint_ident import JointIdentifier
from .regressor import GeometryModel

HARMONICS = 4
BASE_HZ = 0.1  # the series' fundamental: one period is 10 s
FADE_S = 2.0  # s: the envelope's rise and fall
REST_S = 0.5  # s at rest at home before it starts (time to tare)
LIMIT_MARGIN = 0.1  # rad inside each joint limit
SPAN = 1.2  # rad: at most this far from home
# ESTIMATE: what the identified model leaves of a joint signal (N m), to weigh the joint rows: the
# post-fit residuals of ur5e's currents in a typical world were 0.006-0.04 N m
JOINT_RESIDUAL_NM = 0.02


@dataclass(frozen=True)
class Excitation:
    """``q(t) = home + e(t) sum_l (a_l sin(l w t) + b_l cos(l w t) - b_l)``; ``e`` rises and falls as
    ``sin^2`` over ``FADE_S``. Duck-types the world's ``Trajectory`` (``reference(t)``)."""

    home: np.ndarray
    a: np.ndarray  # (n, HARMONICS) rad
    b: np.ndarray
    duration_s: float
    base_hz: float = BASE_HZ
    rest_s: float = REST_S

    def _series(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        w = 2 * math.pi * self.base_hz * np.arange(1, self.a.shape[1] + 1)
        s, c = np.sin(w * t), np.cos(w * t)
        f = (self.a * s + self.b * c).sum(axis=1) - self.b.sum(axis=1)
        df = (self.a * w * c - self.b * w * s).sum(axis=1)
        ddf = (-(self.a * s + self.b * c) * w * w).sum(axis=1)
        return f, df, ddf

    def _envelope(self, t: float) -> tuple[float, float, float]:
        k = math.pi / (2 * FADE_S)
        if t < FADE_S:
            u = k * t
        elif t > self.duration_s - FADE_S:
            u = k * (self.duration_s - t)
            s, c = math.sin(u), math.cos(u)
            return s * s, -2 * k * s * c, -2 * k * k * (c * c - s * s)
        else:
            return 1.0, 0.0, 0.0
        s, c = math.sin(u), math.cos(u)
        return s * s, 2 * k * s * c, 2 * k * k * (c * c - s * s)

    def reference(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = t - self.rest_s
        if t <= 0 or t >= self.duration_s:
            z = np.zeros_like(self.home)
            return self.home.copy(), z, z.copy()
        f, df, ddf = self._series(t)
        e, de, dde = self._envelope(t)
        return self.home + e * f, de * f + e * df, dde * f + 2 * de * df + e * ddf

    def samples(self, rate_hz: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(t, q, qd, qdd) over the whole plan (rest included) at ``rate_hz``."""
        t = np.arange(0.0, self.rest_s + self.duration_s, 1.0 / rate_hz)
        ref = [self.reference(x) for x in t]
        return t, np.array([r[0] for r in ref]), np.array([r[1] for r in ref]), np.array([r[2] for r in ref])


@dataclass
class ExcitationPlan:
    excitation: Excitation
    information: float  # sum log(1 + s_k^2)
    told: int  # directions whose posterior std is below half the prior's
    max_speed: float  # rad/s
    candidates: int
    rejected: dict[str, int]


def plan_excitation(scene: Scene, duration_s: float = 120.0, *, max_speed: float = 1.0, candidates: int = 24,
                    seed: int = 0) -> ExcitationPlan:
    """The most informative of ``candidates`` seeded excitations that respect the limits."""
    arm = ArmModel(scene)
    information = _information(scene, arm)
    lo, hi = joint_limits(GeometryModel(arm)) if scene.robot.flange else arm.joint_limits()
    home = np.asarray(scene.robot.home, dtype=float)
    moving = hi > lo
    lo_ok, hi_ok = np.maximum(lo + LIMIT_MARGIN, home - SPAN), np.minimum(hi - LIMIT_MARGIN, home + SPAN)
    collide = SelfCollision(scene)
    rng = np.random.default_rng(seed)
    best, rejected = None, {"self_collision": 0}
    for _ in range(candidates):
        a, b = (rng.normal(size=(scene.n_joints, HARMONICS)) / np.arange(1, HARMONICS + 1) for _ in range(2))
        a[~moving], b[~moving] = 0.0, 0.0
        exc = _scaled(Excitation(home, a, b, duration_s), lo_ok, hi_ok, max_speed)
        t, q, qd, qdd = exc.samples(2.0)
        if collide.any(q):
            rejected["self_collision"] += 1
            continue
        s = information(q, qd, qdd)
        info = float(np.sum(np.log1p(s * s)))
        if best is None or info > best.information:
            told = int(np.sum(s * s > 3.0))  # posterior std below half the prior's: 1 / (1 + s^2) < 1/4
            best = ExcitationPlan(exc, info, told, float(np.abs(qd).max()), candidates, rejected)
    if best is None:
        raise ValueError(f"none of {candidates} excitations stayed clear of self-collision")
    return best


def _information(scene: Scene, arm: ArmModel):
    """``f(q, qd, qdd) -> s``: the singular values of the whitened, prior-scaled regressor over a
    motion's samples, by what the scene senses (its base F/T sensor, else its joints)."""
    if scene.sensing.ft == "base":
        ident = FreeMotionIdentifier(arm)
        white = 1.0 / np.sqrt(np.diag(scene.sensor.noise_cov))
        prior, rows = ident.prior_sqrt, lambda q, qd, qdd: ident.rows(q, qd, qdd)[0] * white[:, None]
    else:
        joint = JointIdentifier(arm)
        p_in = len(joint.pi0)
        prior, rows = joint.prior_sqrt[:p_in, :p_in], lambda q, qd, qdd: joint.rows(q, qd, qdd)[0] / JOINT_RESIDUAL_NM

    def svd(q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        a = np.vstack([rows(q[k], qd[k], qdd[k]) for k in range(len(q))])
        return np.linalg.svd(a @ prior, compute_uv=False)
    return svd


def _scaled(exc: Excitation, lo: np.ndarray, hi: np.ndarray, max_speed: float) -> Excitation:
    """The same shape, scaled per joint to fill the room about home and to the speed limit."""
    _, q, qd, _ = exc.samples(20.0)  # the peaks between samples: a 3 % margin below
    dev = q - exc.home
    room = np.where(dev.max(axis=0) > 0, 0.97 * (hi - exc.home) / np.maximum(dev.max(axis=0), 1e-12), np.inf)
    room = np.minimum(room, np.where(dev.min(axis=0) < 0,
                                     0.97 * (lo - exc.home) / np.minimum(dev.min(axis=0), -1e-12), np.inf))
    speed = 0.97 * max_speed / np.maximum(np.abs(qd).max(axis=0), 1e-12)
    k = np.minimum(np.minimum(room, speed), 1e3)[:, None]
    k[~np.isfinite(k)] = 0.0
    return Excitation(exc.home, exc.a * k, exc.b * k, exc.duration_s, exc.base_hz, exc.rest_s)


class SelfCollision:
    """The arm's surfaces colliding with each other (parent-child pairs aside, and pairs that already
    overlap at home: they meet at a joint), or a link's origin below the base plane when gravity points
    down its z."""

    def __init__(self, scene: Scene) -> None:
        spec = load_spec(scene)
        for g in spec.geoms:
            on = g.group == SURFACE_GROUP
            g.contype, g.conaffinity = (1, 1) if on else (0, 0)
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        self.scene = scene
        self.down = np.asarray(scene.gravity)[2] < 0 and np.allclose(np.asarray(scene.gravity)[:2], 0.0)
        self.joints = JointMap(self.model, scene)
        self.allowed = self._pairs(np.asarray(scene.robot.home, dtype=float))

    def _pairs(self, q: np.ndarray) -> set[tuple[int, int]]:
        m, d = self.model, self.data
        self.joints.set_qpos(q, d.qpos)
        mujoco.mj_kinematics(m, d)
        mujoco.mj_collision(m, d)
        return {tuple(sorted((int(d.contact[i].geom1), int(d.contact[i].geom2)))) for i in range(d.ncon)}

    def any(self, qs: np.ndarray) -> bool:
        for q in qs:
            if self._pairs(q) - self.allowed:
                return True
            if self.down and np.any(self.data.xpos[2:, 2] < -1e-3):  # (a link frame may sit on the base plane)
                return True
        return False
