"""Scripted contacts of three kinds, each said in the truth (``class``), for classifying contacts (issue 39):

- ``clamping``: a body part against a fixture (a sphere on a stiff spring: the clamped tissue, 5 N/mm) just
  off a surface point; the arm's planned move carries the point into it and keeps pushing (its reference
  goes on past the fixture by the depth that makes ``force`` through the joint controller's stiffness and
  the tissue's in series), holds there, then backs off. The arm cannot move away: the force persists, and
  grows while the reference goes deeper.
- ``guidance``: a hand leads the arm. Its force rises and falls as raised cosines (no jump in its rate: low
  jerk) within 30 deg of the inward normal; the arm yields along it. A position-controlled arm does not
  yield by itself (its joint controller is stiff: a 20 N push moves a UR5e's wrist well under 1 mm), so the
  arm is taken to be in a hand-guiding (admittance) mode: its reference moves the touched point along the
  hand's force at ``|F| / damping`` (m/s), the law an admittance controller with no stiffness and no mass
  applies; after the hand lets go the program takes the arm back to its pose.
- ``impact``: the arm's point moves out along its outward normal and back (1 s, rest to rest), and a
  body part mounted on a soft spring along that line (``Obstacle``: a sphere of a hand's mass, over-damped
  like soft tissue) stands where the point passes at ``speed`` (70 % of the way out). The contact lasts
  while the arm goes on past it and ends as the arm returns: released within about 0.3 s, a transient
  contact.

Every contact is at a visible point of the last three touchable links (their points move with most
joints: what every sensing can see), from the arm's home pose, one after another with the arm back at
home between them; each fixture or body part is there only during its own contact (``Obstacle.from_s`` and
``until_s``). :func:`plan_contacts` returns the setup and the contacts' plan (kind, time window, link,
speed, force) for the bench.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from ftc_hw.geometry.kinds import KINDS
from ftc_hw.geometry.solid import inside_local
from ftc_hw.model import ArmModel, JointMap
from ftc_hw.model.true_arm import compile_true_arm, true_arm_spec
from ftc_hw.scene import Scene

from .touch_points import all_arm_geoms, poke_force_limit, sample_contacts
from .trajectory import Trajectory
from .world import Obstacle, Probe, ScenarioSetup

CONTACT_KINDS = ("clamping", "guidance", "impact")
# what a contact of each kind is classified as, when right: (ContactEvent.contact_class, ContactEvent.intent)
EXPECTED_CLASS = {"clamping": ("quasi_static", "impact"), "impact": ("transient", "impact"),
                  "guidance": ("transient", "guidance")}
REST_S = 0.5  # at rest first: the tare
GAP_S = 0.5  # at rest between two contacts' moves
# ESTIMATE: a slow, a usual and a fast collaborative speed (m/s); ISO/TS 15066's transient limits are met at
# speeds of this order for most body regions (the limits' own figures: the `limits` part of issue 39)
IMPACT_SPEEDS = (0.15, 0.3, 0.5)
BODY_MASS_KG = 0.6  # ESTIMATE: about a hand's mass (the mass a struck hand or forearm moves at first)
SPHERE_RADIUS_M = 0.03
MAX_JOINT_MOVE = 0.6  # rad: a contact's move larger than this at any joint is not planned (a near-singular point)
CLAMPED_N_PER_M = 5000.0  # ESTIMATE: a clamped hand or forearm with the fixture's padding (ISO/TS 15066's body
# regions are stiffer, 10-75 N/mm: a softer spring keeps the force near the plan when the true shell is off the model's)
GUIDE_DAMPING = (150.0, 400.0)  # N s/m, ESTIMATE: an admittance's damping for hand guiding: 20 N moves 0.05-0.13 m/s
GUIDE_MIN_MPS = 0.04  # the slowest guided speed planned (a small arm's, whose joints a longer path takes too far)
# a hand leads the arm only where its joints can move the point along the push: at least this share of the
# planned motion along it (a push along a link's own joint axis, or radially on the first link of leng2016's
# 3-joint arm, holds the arm still: it cannot be told from a clamp, and a person would not lead it so)
YIELDS_ALONG = 0.9


@dataclass(frozen=True)
class PlannedContact:
    """One scripted contact: its kind, its time window (s, scenario time), where, how fast and how hard."""

    kind: str
    t_start: float  # the move (or the hand's force) starts
    t_end: float  # the move is over (the contact was released before)
    link: str
    speed: float  # m/s: the point's speed at the touch (impact), the guided peak speed, the approach's peak
    force: float  # N: the hand's force, the clamp's planned force, the impact body's planned peak


@dataclass(frozen=True)
class Moves(Trajectory):
    """Home plus joint displacements, each along its own direction by a sampled path: ``q = home + sum_i
    dq_i s_i(t - t0_i)`` (s_i, its rate and acceleration sampled every ``dt``, linear between)."""

    home: np.ndarray
    dq: tuple[np.ndarray, ...]
    t0: tuple[float, ...]
    paths: tuple[np.ndarray, ...]  # each (k, 3): s, ds/dt, d2s/dt2
    dt: float = 1e-3

    def reference(self, t: float):
        q, qd, qdd = self.home.copy(), np.zeros_like(self.home), np.zeros_like(self.home)
        for dq, t0, path in zip(self.dq, self.t0, self.paths, strict=True):
            u = (t - t0) / self.dt
            if u <= 0.0:
                continue
            i = min(int(u), len(path) - 2)
            w = min(u - i, 1.0)
            s, sd, sdd = (1 - w) * path[i] + w * path[i + 1]
            q += dq * s
            qd += dq * sd
            qdd += dq * sdd
        return q, qd, qdd


def _min_jerk(a: float, b: float, t: np.ndarray, duration: float) -> np.ndarray:
    """(k, 3) min-jerk move from a to b over ``duration``: position, rate, acceleration at times t."""
    x = np.clip(t / duration, 0.0, 1.0)
    d = b - a
    inside = (t > 0) & (t < duration)
    return np.stack([a + d * (10 * x**3 - 15 * x**4 + 6 * x**5),
                     inside * d * (30 * x**2 - 60 * x**3 + 30 * x**4) / duration,
                     inside * d * (60 * x - 180 * x**2 + 120 * x**3) / duration**2], axis=1)


def _out_back(amplitude: float, period: float, t: np.ndarray) -> np.ndarray:
    """(k, 3) ``s = amplitude (1 - cos(w t))^2 / 4`` over one period: out to ``amplitude`` and back, from rest
    to rest with no jump in the acceleration (a planned move's)."""
    w = 2 * math.pi / period
    inside = (t > 0) & (t < period)
    c, s = np.cos(w * t), np.sin(w * t)
    return np.stack([inside * amplitude * (1 - c) ** 2 / 4, inside * amplitude * w * (1 - c) * s / 2,
                     inside * amplitude * w * w * (s * s + (1 - c) * c) / 2], axis=1)


class _Site:
    """A touch site: a visible point of a distal link at home, its outward normal and the joint move that
    carries the point along a direction (damped least squares on its Jacobian)."""

    def __init__(self, model: ArmModel, home: np.ndarray, rng: np.random.Generator, links: frozenset[str]) -> None:
        self.model, self.home = model, home
        for _ in range(200):
            (sp, force), = sample_contacts(model, home, 1, rng, 30.0, (1.0, 1.0))
            if sp.link in links:
                break
        self.point, self.normal, self.link, self.push = sp.point, sp.normal, sp.link, force / np.linalg.norm(force)
        b_T_l = model.kinematics(home)[sp.link]
        self.point_link = b_T_l[:3, :3].T @ (sp.point - b_T_l[:3, 3])
        self.normal_link = b_T_l[:3, :3].T @ sp.normal
        self.geom = sp.geom
        self.jac = model.jacobian(home, sp.link, sp.point)

    def joint_move(self, direction: np.ndarray) -> np.ndarray:
        """dq (rad per m) moving the point along ``direction`` (unit, base frame) at first order."""
        j = self.jac
        lam2 = 1e-4  # m^2: damping of the least squares near a singularity
        return j.T @ np.linalg.solve(j @ j.T + lam2 * np.eye(3), direction)

    def stiffness_along(self, direction: np.ndarray, kp: np.ndarray) -> float:
        """N/m: the joint controller's stiffness at the point along ``direction`` (static: J K^-1 J^T)."""
        compliance = float(direction @ (self.jac / kp) @ self.jac.T @ direction)
        return 1.0 / max(compliance, 1e-9)

    def posed(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The point and its outward normal (base frame) at q."""
        b_T_l = self.model.kinematics(q)[self.link]
        return b_T_l[:3, :3] @ self.point_link + b_T_l[:3, 3], b_T_l[:3, :3] @ self.normal_link


CLEARANCE_M = 0.005  # a body part keeps this off the arm at home (a typical world shifts the shell by 1-2 mm)


class _Clearance:
    """Whether a body part at home stays clear of the arm: of the model's primitives and of the surface the
    scene's world collides (a vendor's meshes, each part as its convex hull, which bridges its hollows: it
    stands out of the primitives by centimetres in places)."""

    def __init__(self, scene: Scene, model: ArmModel, home: np.ndarray) -> None:
        self.model, self.home = model, home
        spec = true_arm_spec(scene, shell="collide")
        probe = spec.worldbody.add_body(name="ftc_clearance", mocap=True)
        probe.add_geom(name="ftc_clearance_geom", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[SPHERE_RADIUS_M, 0, 0],
                       contype=2, conaffinity=1, group=2)
        self.m = m = compile_true_arm(scene, spec)
        self.d = mujoco.MjData(m)
        JointMap(m, scene).set_qpos(home, self.d.qpos)
        self.geom = m.geom("ftc_clearance_geom").id
        self.arm = [g for g in range(m.ngeom) if g != self.geom and (m.geom_conaffinity[g] & 2 or m.geom_contype[g] & 1)
                    and m.geom_bodyid[g] != 0]

    def clear(self, centre: np.ndarray, radius: float) -> bool:
        for _, kind, size, b_T_g in all_arm_geoms(self.model, self.home):
            local = b_T_g[:3, :3].T @ (centre - b_T_g[:3, 3])
            if inside_local(KINDS[kind], size, local, -(radius + CLEARANCE_M)):
                return False
        self.d.mocap_pos[0] = centre
        mujoco.mj_forward(self.m, self.d)
        ft = np.zeros(6)
        return all(mujoco.mj_geomDistance(self.m, self.d, self.geom, g, 0.1, ft) > CLEARANCE_M for g in self.arm)


def _force_range(scene: Scene) -> tuple[float, float]:
    top = poke_force_limit(scene)
    return 0.25 * top, 0.6 * top


def plan_contacts(scene: Scene, model: ArmModel, rng: np.random.Generator, kinds: tuple[str, ...],
                  count: int, clearance: _Clearance | None = None) -> tuple[ScenarioSetup, tuple[PlannedContact, ...]]:
    """``count`` contacts of each of ``kinds`` (interleaved: one of each in turn), one after another from
    home; the setup and the plan. ``clearance``: where a body part may stand (built here if not given)."""
    home = np.asarray(scene.robot.home, dtype=float)
    kp = np.asarray(scene.robot.kp, dtype=float)
    links = frozenset(t.link for t in scene.touchable[-3:])
    dqs, t0s, paths, probes, obstacles, plan = [], [], [], [], [], []
    t = REST_S
    order = [k for _ in range(count) for k in kinds]
    clearance = clearance or _Clearance(scene, model, home)
    for i, kind in enumerate(order):
        for _ in range(200):  # a site whose move is small enough and whose body is clear of the arm
            site = _Site(model, home, rng, links)
            made = _BUILDERS[kind](site, scene, kp, rng, t, i, clearance)
            if made is not None:
                break
        else:
            raise RuntimeError(f"{scene.name}: no site found for a {kind} contact")
        dq, path, probe, obstacle, contact = made
        dqs.append(dq)
        t0s.append(t)
        paths.append(path)
        probes += [probe] if probe is not None else []
        obstacles += [obstacle] if obstacle is not None else []
        plan.append(contact)
        t = max(contact.t_end, t + (len(path) - 1) * 1e-3) + GAP_S
    traj = Moves(home, tuple(dqs), tuple(t0s), tuple(paths))
    return ScenarioSetup(traj, probes=tuple(probes), obstacles=tuple(obstacles)), tuple(plan)


def _times(duration: float, dt: float = 1e-3) -> np.ndarray:
    return np.arange(0.0, duration + 2 * dt, dt)


def _impact(site: _Site, scene: Scene, kp, rng, t0: float, i: int, clearance: _Clearance):
    speed = IMPACT_SPEEDS[(i // 3) % len(IMPACT_SPEEDS)]
    period = 1.0
    phase = 0.7  # the point touches at 70 % of its excursion, on its way out
    theta = math.acos(1 - 2 * math.sqrt(phase))
    amplitude = speed * period / (math.pi * (1 - math.cos(theta)) * math.sin(theta))
    dq = site.joint_move(site.normal)
    if np.abs(dq * amplitude).max() > MAX_JOINT_MOVE:
        return None
    touch = site.home + dq * amplitude * phase
    point, normal = site.posed(touch)
    centre = point + normal * (SPHERE_RADIUS_M + 1e-3)
    if not clearance.clear(centre, SPHERE_RADIUS_M):
        return None
    lo, hi = _force_range(scene)
    peak = float(rng.uniform(lo, hi))
    travel = amplitude * (1 - phase)  # how far the arm goes on past the touch
    stiffness = peak / travel
    damping = 4.0 * math.sqrt(stiffness * BODY_MASS_KG)  # over-damped (twice critical): soft tissue, no rebound
    t_end = t0 + period
    obstacle = Obstacle(centre, SPHERE_RADIUS_M, normal, stiffness=stiffness, damping=damping, mass=BODY_MASS_KG,
                        from_s=t0, until_s=t_end + 0.2, label="impact")
    path = _out_back(amplitude, period, _times(period))
    return dq, path, None, obstacle, PlannedContact("impact", t0, t_end + 0.2, site.link, speed, peak)


def _clamping(site: _Site, scene: Scene, kp, rng, t0: float, i: int, clearance: _Clearance):
    gap = 0.02  # m from the point to the fixture at home
    lo, hi = _force_range(scene)
    force = float(rng.uniform(lo, hi))
    press = force * (1 / site.stiffness_along(site.normal, kp) + 1 / CLAMPED_N_PER_M)  # past the fixture
    dq = site.joint_move(site.normal)
    reach = gap + press
    if np.abs(dq * reach).max() > MAX_JOINT_MOVE:
        return None
    point, normal = site.posed(site.home + dq * gap)
    centre = point + normal * (SPHERE_RADIUS_M + 1e-3)
    if not clearance.clear(centre, SPHERE_RADIUS_M):
        return None
    move, hold = 0.8, float(rng.uniform(1.2, 2.0))
    ts = _times(2 * move + hold)
    path = _min_jerk(0.0, reach, ts, move)
    back = _min_jerk(reach, 0.0, ts - move - hold, move)
    path = np.where((ts > move + hold)[:, None], back, path)
    t_end = t0 + 2 * move + hold
    mass = 1.0
    fixture = Obstacle(centre, SPHERE_RADIUS_M, normal, stiffness=CLAMPED_N_PER_M,
                       damping=2 * math.sqrt(CLAMPED_N_PER_M * mass), mass=mass, from_s=t0, until_s=t_end + 0.2,
                       label="clamping")
    return dq, path, None, fixture, PlannedContact("clamping", t0, t_end + 0.2, site.link, 1.875 * reach / move, force)


def _guidance(site: _Site, scene: Scene, kp, rng, t0: float, i: int, clearance: _Clearance):
    lo, hi = _force_range(scene)
    force = float(rng.uniform(lo, hi))
    ramp, hold = float(rng.uniform(0.4, 0.8)), float(rng.uniform(0.8, 1.6))
    damping = float(rng.uniform(*GUIDE_DAMPING)) * force / 20.0  # the same speeds whatever the force
    direction = site.push
    dq = site.joint_move(direction)
    if float(direction @ site.jac @ dq) < YIELDS_ALONG:  # the joints cannot move the point along the push
        return None
    travel = force * (ramp + hold) / damping  # the point's path along the force: the integral of |F| / D
    # a small arm is led more slowly (a longer path would take its joints far): down to GUIDE_MIN_MPS
    damping *= max(1.0, float(np.abs(dq).max()) * travel / MAX_JOINT_MOVE)
    if force / damping < GUIDE_MIN_MPS:
        return None
    probe = Probe(site.link, site.point_link, direction, force, t0, ramp_s=ramp, hold_s=hold,
                  normal_link=site.normal_link, geom=site.geom, smooth=True, label="guidance")
    ts = _times(2 * ramp + hold)
    f = np.array([probe.magnitude_at(t0 + t) for t in ts])
    sd = f / damping
    s = np.concatenate([[0.0], np.cumsum(0.5 * (sd[1:] + sd[:-1]) * np.diff(ts))])
    sdd = np.gradient(sd, ts)
    travel = float(s[-1])
    back_s = 1.2
    tb = _times(2 * ramp + hold + 0.3 + back_s)
    led = np.zeros((len(tb), 3))
    led[:len(ts)] = np.stack([s, sd, sdd], axis=1)
    led[len(ts):, 0] = travel
    after = tb - (2 * ramp + hold + 0.3)
    led = np.where((after > 0)[:, None], _min_jerk(travel, 0.0, after, back_s), led)
    t_end = t0 + 2 * ramp + hold
    return dq, led, probe, None, PlannedContact("guidance", t0, t_end, site.link, float(sd.max()), force)


_BUILDERS = {"impact": _impact, "clamping": _clamping, "guidance": _guidance}


def plan_within(scene: Scene, model: ArmModel, rng: np.random.Generator, kinds: tuple[str, ...],
                duration: float) -> ScenarioSetup:
    """As many contacts of each of ``kinds`` as end within ``duration`` (at least one of each)."""
    seed = int(rng.integers(2**31))
    best = None
    clearance = _Clearance(scene, model, np.asarray(scene.robot.home, dtype=float))
    for count in range(1, 1000):
        setup, plan = plan_contacts(scene, model, np.random.default_rng(seed), kinds, count, clearance)
        if best is not None and run_length(plan) > duration:
            break
        best = setup
    return best


def run_length(plan: tuple[PlannedContact, ...]) -> float:
    """s: the last contact's window, the arm back home, and a rest."""
    return max(c.t_end for c in plan) + 2.0
