"""Named scenarios: what the arm does and what touches it. ``ftc sim --list`` shows them."""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np

from ftc_hw.calibration.excitation import FADE_S, plan_excitation
from ftc_hw.calibration.excitation import REST_S as EXCITATION_REST_S
from ftc_hw.geometry.kinds import KINDS
from ftc_hw.geometry.solid import inside_local
from ftc_hw.model import ArmModel, Payload
from ftc_hw.model.arm import GEOM_KINDS, SURFACE_GROUP, pose
from ftc_hw.model.sampling import SurfacePoint, sample_surface_points
from ftc_hw.scene import Scene

from .trajectory import Hold, PointToPoint, Sinusoid
from .world import Obstacle, Probe, ScenarioSetup


@dataclass(frozen=True)
class ScenarioInfo:
    name: str
    description: str
    build: Callable[..., ScenarioSetup]


def poke_force_limit(scene: Scene) -> float:
    """Largest poke (N): a fifth of a base F/T sensor's smallest force range, at most 100 N (a flange
    sensor does not carry the arm's pokes: 100 N)."""
    s = scene.sensor
    return float(min(100.0, 0.2 * s.range[:3].min())) if s is not None and s.mount == "base" else 100.0


def random_pokes(model: ArmModel, q, rng: np.random.Generator, count: int, t0: float = 0.2,
                 period: float = 0.5, f_min: float = 5.0, f_max: float | None = None,
                 max_angle_deg: float = 45.0) -> tuple[Probe, ...]:
    """Pokes at points uniform on the touchable surfaces, pushing into the surface within a cone."""
    f_max = f_max or poke_force_limit(model.scene)
    points = sample_surface_points(model, q, count, rng, hidden=visible_filter(model, q))
    links = model.kinematics(q)
    probes = []
    for i, sp in enumerate(points):
        direction = _cone(-sp.normal, math.radians(max_angle_deg), rng)
        base_T_link = links[sp.link]
        point_link = base_T_link[:3, :3].T @ (sp.point - base_T_link[:3, 3])
        normal_link = base_T_link[:3, :3].T @ sp.normal
        probes.append(Probe(sp.link, point_link, direction, float(rng.uniform(f_min, f_max)), t0 + i * period,
                            normal_link=normal_link, geom=sp.geom))
    return tuple(probes)


def sample_contacts(model: ArmModel, q, n: int, rng: np.random.Generator, max_angle_deg: float,
                    f_range: tuple[float, float]) -> list[tuple[SurfacePoint, np.ndarray]]:
    """(surface point, force applied to the arm) pairs: points uniform on the visible touchable
    surfaces, forces pushing in within a cone about the inward normal, magnitudes uniform in f_range."""
    points = sample_surface_points(model, q, n, rng, hidden=visible_filter(model, q))
    return [(sp, _cone(-sp.normal, math.radians(max_angle_deg), rng) * rng.uniform(*f_range)) for sp in points]


def visible_filter(model: ArmModel, q, eps: float = 1e-8):
    """A ``hidden(point, normal, posed_surface)`` predicate: true when the point is not on the arm's
    outer surface, by the solver's own rule (the point just outside it lies inside another geom)."""
    others = _all_arm_geoms(model, q)

    def hidden(point: np.ndarray, normal: np.ndarray, ps) -> bool:
        y = point + eps * normal
        for name, kind, size, b_T_g in others:
            if name == ps.surface.geom:
                continue
            local = b_T_g[:3, :3].T @ (y - b_T_g[:3, 3])
            if inside_local(KINDS[kind], size, local, 0.0):
                return True
        return False

    return hidden


def _all_arm_geoms(model: ArmModel, q):
    """Every group-1 primitive of the arm (touchable or not) with its pose: what can hide a point."""
    model.kinematics(q)
    m, d = model.model, model.data
    out = []
    for g in range(m.ngeom):
        kind = GEOM_KINDS.get(int(m.geom_type[g]))
        if m.geom_group[g] != SURFACE_GROUP or kind is None:
            continue
        out.append((m.geom(g).name, kind, m.geom_size[g].copy(), pose(d.geom_xmat[g].reshape(3, 3), d.geom_xpos[g])))
    return out


def _cone(axis: np.ndarray, max_angle: float, rng: np.random.Generator) -> np.ndarray:
    """A unit vector within ``max_angle`` of ``axis`` (uniform over the cone's solid angle)."""
    axis = axis / np.linalg.norm(axis)
    cos_a = rng.uniform(math.cos(max_angle), 1.0)
    phi = rng.uniform(0.0, 2 * math.pi)
    helper = np.array([1.0, 0, 0]) if abs(axis[0]) < 0.9 else np.array([0, 1.0, 0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    sin_a = math.sqrt(max(0.0, 1 - cos_a * cos_a))
    return cos_a * axis + sin_a * (math.cos(phi) * u + math.sin(phi) * v)


# -- builders ----------------------------------------------------------------------------------------
WHOLE_CONTACT_MARGIN_S = 0.1  # a scripted contact is planned only if it ends this long before the run's end


def build_hold(scene: Scene, model: ArmModel, rng: np.random.Generator, duration: float) -> ScenarioSetup:
    return ScenarioSetup(Hold(np.array(scene.robot.home)))


def build_static_pokes(scene: Scene, model: ArmModel, rng: np.random.Generator, duration: float) -> ScenarioSetup:
    q = np.array(scene.robot.home)
    # pokes at 0.2 s + 0.5 s i, 0.3 s each: those that end within the run (at least one)
    count = max(1, math.floor((duration - WHOLE_CONTACT_MARGIN_S - 0.5) / 0.5) + 1)
    return ScenarioSetup(Hold(q), probes=random_pokes(model, q, rng, count))


SWEEP_REST_S = 0.3  # the sweeps start with the arm at rest, long enough to tare the sensor


def sweep_trajectory(scene: Scene, speed: float = 1.0) -> Sinusoid:
    """Base joint sweeps +-0.6 rad, the next joint +-0.25 rad, at 0.25 Hz x speed, from rest at the
    low end of the swing (after SWEEP_REST_S at rest)."""
    n = scene.n_joints
    amp = np.zeros(n)
    amp[0] = 0.6
    if n > 1:
        amp[1] = 0.25
    return Sinusoid(np.array(scene.robot.home), amp, 0.25 * speed, start_s=SWEEP_REST_S)


def build_sweep(scene: Scene, model: ArmModel, rng: np.random.Generator, duration: float,
                speed: float = 1.0) -> ScenarioSetup:
    return ScenarioSetup(sweep_trajectory(scene, speed))


def build_sweep_with_collision(scene: Scene, model: ArmModel, rng: np.random.Generator, duration: float,
                               speed: float = 1.0, peak_force: float = 40.0) -> ScenarioSetup:
    """The sweep, with a compliant sphere placed where the most distal touchable link passes.

    The obstacle sits just off the link's surface at 70 % of the first swing, on a spring along the
    direction of motion whose stiffness makes the peak force about ``peak_force`` N at the swing's end.
    It meets every swing that ends within ``duration`` (at least the first), then is withdrawn, so no
    contact is cut short by the run's end.
    """
    traj = sweep_trajectory(scene, speed)
    period = 1.0 / traj.frequency_hz
    # sin(w t + phase) = 0.7 on the way up to its peak at sin = 1, and again on the way back
    t_touch = traj.start_s + (math.asin(0.7) - traj.phase) / (2 * math.pi) * period
    t_peak = traj.start_s + (math.pi / 2 - traj.phase) / (2 * math.pi) * period
    t_leave = traj.start_s + (math.pi - math.asin(0.7) - traj.phase) / (2 * math.pi) * period
    swings = max(1, math.floor((duration - WHOLE_CONTACT_MARGIN_S - t_leave) / period) + 1)
    # at the low end of the swing after the last one: the arm is furthest from the obstacle
    until = traj.start_s + (swings + (-math.pi / 2 - traj.phase) / (2 * math.pi)) * period
    q_touch, _, _ = traj.reference(t_touch)
    q_peak, _, _ = traj.reference(t_peak)
    link = scene.touchable[-1].link
    links = model.kinematics(q_touch)
    b_T_l = links[link]
    surfaces = [s for s in model.surfaces if s.link == link]
    centre_local = surfaces[0].link_T_geom[:3, 3]
    centre = b_T_l[:3, :3] @ centre_local + b_T_l[:3, 3]
    after = model.kinematics(q_peak)[link]
    centre_peak = after[:3, :3] @ centre_local + after[:3, 3]
    travel = centre_peak - centre
    v = travel / np.linalg.norm(travel)
    surface = _ray_to_surface(model, q_touch, centre + v, -v)
    radius = 0.03
    position = surface + v * (radius + 1e-3)
    penetration = max(float(travel @ v) - 1e-3, 1e-3)
    stiffness = peak_force / penetration
    mass = 0.3
    # Heavily over-damped, like soft tissue: it creeps back after the arm leaves instead of chasing it.
    obstacle = Obstacle(position, radius, v, stiffness=stiffness, damping=2.0 * math.sqrt(stiffness * mass), mass=mass,
                        until_s=until)
    return ScenarioSetup(traj, obstacles=(obstacle,))


def _ray_to_surface(model: ArmModel, q, origin: np.ndarray, direction: np.ndarray) -> np.ndarray:
    model.kinematics(q)
    groups = np.array([0, 1, 0, 0, 0, 0], dtype=np.uint8)
    geomid = np.array([-1], dtype=np.int32)
    dist = mujoco.mj_ray(model.model, model.data, origin, direction, groups, 1, -1, geomid)
    if dist < 0:
        raise RuntimeError("the sweep's obstacle placement ray missed the arm")
    return origin + dist * direction


def build_payload_poses(scene: Scene, model: ArmModel, rng: np.random.Generator, duration: float) -> ScenarioSetup:
    """A 0.5 kg payload on the flange, moved through static poses (1.5 s moves, 1.5 s holds)."""
    home = np.array(scene.robot.home)
    n_poses = max(2, int(duration / 3.0) + 1)
    lo, hi = model.joint_limits()
    poses = [home]
    for _ in range(n_poses - 1):
        poses.append(np.clip(home + rng.uniform(-0.6, 0.6, scene.n_joints), lo, hi))
    return ScenarioSetup(PointToPoint(np.array(poses), 1.5, 1.5), payload=Payload(0.5, (0.0, 0.0, 0.05)))


def build_excitation(scene: Scene, model: ArmModel, rng: np.random.Generator, duration: float) -> ScenarioSetup:
    """The planned excitation for identification (ftc identify --plan), filling the run."""
    plan = plan_excitation(scene, max(duration - EXCITATION_REST_S, 2 * FADE_S + 1.0), seed=int(rng.integers(2**31)))
    return ScenarioSetup(plan.excitation)


SCENARIOS: dict[str, ScenarioInfo] = {s.name: s for s in [
    ScenarioInfo("hold", "the arm holds its home pose; nothing touches it", build_hold),
    ScenarioInfo("static-pokes", "the arm holds its home pose; a probe pokes random surface points "
                 "(5 N to the scene's poke limit, within 45 degrees of the inward normal), one every 0.5 s, "
                 "each ending within the run",
                 build_static_pokes),
    ScenarioInfo("sweep", "sinusoidal sweep of the first two joints (0.25 Hz); no contact", build_sweep),
    ScenarioInfo("sweep-with-collision", "the sweep; the most distal link hits a compliant obstacle "
                 "(about 40 N peak) once per swing, on every swing that ends within the run",
                 build_sweep_with_collision),
    ScenarioInfo("excitation", "a planned identification motion: every joint on a Fourier series about home, "
                 "within its limits, 1 rad/s and clear of self-collision (ftc identify --plan)", build_excitation),
    ScenarioInfo("payload-poses", "a 0.5 kg payload on the flange; the arm moves through static poses",
                 build_payload_poses),
]}


def build_scenario(name: str, scene: Scene, model: ArmModel, seed: int, duration: float,
                   **params) -> ScenarioSetup:
    if name not in SCENARIOS:
        raise KeyError(f"unknown scenario {name!r} (known: {', '.join(SCENARIOS)})")
    rng = np.random.default_rng(seed)
    return SCENARIOS[name].build(scene, model, rng, duration, **params)
