"""Named scenarios: what the arm does and what touches it. ``ftc sim --list`` shows them."""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np

from ftc_hw.calibration.excitation import FADE_S, plan_excitation
from ftc_hw.calibration.excitation import REST_S as EXCITATION_REST_S
from ftc_hw.model import ArmModel, Payload
from ftc_hw.scene import Scene

from .contact_kinds import plan_within
from .touch_points import _cone, poke_force_limit, random_pokes, sample_contacts, visible_filter
from .trajectory import Hold, PointToPoint, Sinusoid
from .world import Obstacle, Probe, ScenarioSetup

# the touch points' helpers, where the tests and benches import them from
__all__ = ["SCENARIOS", "ScenarioInfo", "_cone", "build_scenario", "poke_force_limit",
           "random_pokes", "sample_contacts", "visible_filter"]


@dataclass(frozen=True)
class ScenarioInfo:
    name: str
    description: str
    build: Callable[..., ScenarioSetup]


# -- builders ----------------------------------------------------------------------------------------
WHOLE_CONTACT_MARGIN_S = 0.1  # a scripted contact is planned only if it ends this long before the run's end


def build_hold(scene: Scene, model: ArmModel, rng: np.random.Generator, duration: float) -> ScenarioSetup:
    return ScenarioSetup(Hold(np.array(scene.robot.home)))


def build_static_pokes(scene: Scene, model: ArmModel, rng: np.random.Generator, duration: float) -> ScenarioSetup:
    q = np.array(scene.robot.home)
    # pokes at 0.2 s + 0.5 s i, 0.3 s each: those that end within the run (at least one)
    count = max(1, math.floor((duration - WHOLE_CONTACT_MARGIN_S - 0.5) / 0.5) + 1)
    return ScenarioSetup(Hold(q), probes=random_pokes(model, q, rng, count))


PRESS_HOLDS_S = (0.2, 2.0)  # static-presses: a poke's hold, then a press's, in turn
PRESS_GAP_S = 0.2  # between one's end and the next's start


def build_static_presses(scene: Scene, model: ArmModel, rng: np.random.Generator, duration: float) -> ScenarioSetup:
    """Pokes (0.3 s) and presses (2.1 s) in turn from 0.2 s, 0.2 s apart: those that end within the run."""
    q = np.array(scene.robot.home)
    starts, t = [], 0.2
    while True:
        hold = PRESS_HOLDS_S[len(starts) % 2]
        if starts and t + 2 * Probe.ramp_s + hold > duration - WHOLE_CONTACT_MARGIN_S:
            break
        starts.append((t, hold))
        t += 2 * Probe.ramp_s + hold + PRESS_GAP_S
    probes = random_pokes(model, q, rng, len(starts))
    return ScenarioSetup(Hold(q), probes=tuple(dataclasses.replace(p, t_start=t0, hold_s=hold)
                                               for p, (t0, hold) in zip(probes, starts, strict=True)))


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


def _kinds(*kinds: str) -> Callable[..., ScenarioSetup]:
    def build(scene: Scene, model: ArmModel, rng: np.random.Generator, duration: float) -> ScenarioSetup:
        return plan_within(scene, model, rng, kinds, duration)
    return build


SCENARIOS: dict[str, ScenarioInfo] = {s.name: s for s in [
    ScenarioInfo("hold", "the arm holds its home pose; nothing touches it", build_hold),
    ScenarioInfo("static-pokes", "the arm holds its home pose; a probe pokes random surface points "
                 "(5 N to the scene's poke limit, within 45 degrees of the inward normal), one every 0.5 s, "
                 "each ending within the run",
                 build_static_pokes),
    ScenarioInfo("static-presses", "as static-pokes, but a poke (0.3 s) and a press (2.1 s) in turn, 0.2 s apart: "
                 "a contact that outlasts a loaded cell's delivery lag (a stream cut in it is cut mid-contact)",
                 build_static_presses),
    ScenarioInfo("sweep", "sinusoidal sweep of the first two joints (0.25 Hz); no contact", build_sweep),
    ScenarioInfo("sweep-with-collision", "the sweep; the most distal link hits a compliant obstacle "
                 "(about 40 N peak) once per swing, on every swing that ends within the run",
                 build_sweep_with_collision),
    ScenarioInfo("excitation", "a planned identification motion: every joint on a Fourier series about home, "
                 "within its limits, 1 rad/s and clear of self-collision (ftc identify --plan)", build_excitation),
    ScenarioInfo("payload-poses", "a 0.5 kg payload on the flange; the arm moves through static poses",
                 build_payload_poses),
    ScenarioInfo("clamping", "from home, the arm moves a distal point into a fixture and keeps pushing (the "
                 "force persists while the arm cannot move away), then backs off; truth class clamping",
                 _kinds("clamping")),
    ScenarioInfo("guidance", "a hand leads the arm by a distal point (its force rises and falls smoothly); the "
                 "arm yields along it (a hand-guiding mode), then returns home; truth class guidance",
                 _kinds("guidance")),
    ScenarioInfo("impacts", "the arm's distal point moves out and back at 0.15, 0.3, 0.5 m/s and strikes a body "
                 "part on a soft spring, released within about 0.2 s; truth class impact", _kinds("impact")),
    ScenarioInfo("contact-kinds", "clamping, guidance and impacts in turn (sim_devices/world/contact_kinds.py)",
                 _kinds("clamping", "guidance", "impact")),
]}


def build_scenario(name: str, scene: Scene, model: ArmModel, seed: int, duration: float,
                   **params) -> ScenarioSetup:
    if name not in SCENARIOS:
        raise KeyError(f"unknown scenario {name!r} (known: {', '.join(SCENARIOS)})")
    rng = np.random.default_rng(seed)
    return SCENARIOS[name].build(scene, model, rng, duration, **params)
