"""Joint-signal contact sensing against the simulated world (issue 37): the :class:`JointContactPipeline`
driven by the arm's joint samples (motor currents or joint torques) while every joint sweeps, and probes
press random visible surface points in force bands.

- free run (no probe): false alarms per minute (an onset with no contact in the world within 0.1 s);
- probed run: per probe, detected (an onset while it presses), the delay from its first newton, its
  force band; per event in contact (onset and updates): link right, flagged ``ambiguous``, the point's
  error against the world's truth and whether the truth lies within the 95 % ellipsoid of the reported
  standard deviations (``coverage``, over unflagged events).

The world is the scene's own (``ideal``) or a seeded draw of another arm (``typical``, ``harsh``:
``sim_devices/world/reality.py``), without identification unless ``corrections`` are given.
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ftc_hw.bench.detectable import SPEED_EDGES, link_threshold, probe_d2
from ftc_hw.model import ArmModel
from ftc_hw.model.inertials import body_params
from ftc_hw.model.true_arm import compile_true_arm, true_arm_spec
from ftc_hw.pipeline import Corrections, JointContactPipeline, PipelineSettings
from ftc_hw.scene import Scene, load_scene
from ftc_hw.sim_devices.world import Probe, ScenarioSetup, World, with_reality
from ftc_hw.sim_devices.world.scenarios import sample_contacts
from ftc_hw.sim_devices.world.trajectory import Trajectory

BANDS = ((5.0, 10.0), (10.0, 25.0), (25.0, 50.0), (50.0, 100.0))
CHI2_3_95 = 7.815
REST_S = 0.5


@dataclass(frozen=True)
class MultiSine(Trajectory):
    """Every joint ``q = centre + amplitude (1 - cos(2 pi f t)) / 2``, its own frequency: starts at rest, and
    the joints' reversals (where their friction flips) fall at different times."""

    centre: np.ndarray
    amplitude: np.ndarray
    frequency_hz: np.ndarray
    start_s: float = REST_S

    def reference(self, t: float):
        w = 2 * np.pi * self.frequency_hz
        u = max(t - self.start_s, 0.0)
        on = 1.0 if t > self.start_s else 0.0
        return (self.centre + self.amplitude * (1 - np.cos(w * u)) / 2, on * self.amplitude * w * np.sin(w * u) / 2,
                on * self.amplitude * w * w * np.cos(w * u) / 2)


def sweep(scene: Scene, speed: float = 1.0) -> MultiSine:
    n = scene.n_joints
    freqs = speed * np.array([0.13, 0.17, 0.21, 0.11, 0.23, 0.19, 0.15, 0.25])[:n]
    amp = np.array([0.5, 0.3, 0.3, 0.4, 0.4, 0.5, 0.4, 0.3])[:n]
    return MultiSine(np.asarray(scene.robot.home, dtype=float), amp, freqs)


def arm_rate(scene: Scene) -> float:
    for d in scene.devices:
        if d.kind == "ur-rtde":
            return float(d.params.get("frequency", 500.0))
    return 1000.0 if scene.joint_torque is not None else 500.0


def probes(scene: Scene, model: ArmModel, traj: Trajectory, count: int, rng: np.random.Generator,
           period_s: float = 1.0, hold_s: float = 0.3, ramp_s: float = 0.01,
           links: frozenset[str] | None = None) -> tuple[Probe, ...]:
    """``count`` probes, one every ``period_s`` after the rest, each at a visible surface point (of ``links``
    only, if given) at the arm's pose mid-press, pushing within 30 deg of the inward normal, magnitude
    uniform in a band (in turn)."""
    out = []
    for i in range(count):
        t0 = REST_S + 1.0 + i * period_s
        q, _, _ = traj.reference(t0 + ramp_s + hold_s / 2)
        lo, hi = BANDS[i % len(BANDS)]
        drawn = sample_contacts(model, q, 1 if links is None else 60, rng, 30.0, (lo, hi))
        sp, force = next((x for x in drawn if links is None or x[0].link in links), drawn[0])
        b_T_l = model.kinematics(q)[sp.link]
        local = b_T_l[:3, :3].T @ (sp.point - b_T_l[:3, 3])
        normal = b_T_l[:3, :3].T @ sp.normal
        mag = float(np.linalg.norm(force))
        out.append(Probe(sp.link, local, force / mag, mag, t_start=t0, ramp_s=ramp_s, hold_s=hold_s,
                         normal_link=normal, geom=sp.geom))
    return tuple(out)


def run_world(scene: Scene, world_scene: Scene, setup: ScenarioSetup, duration: float, seed: int,
              settings: PipelineSettings | None = None) -> dict[str, Any]:
    """The pipeline over ``duration`` s of the world: its onsets, its events in contact with the truth, and
    its per-frame cost (s)."""
    world = World(world_scene, setup, seed=seed)
    pipe = JointContactPipeline(scene, settings)
    every = max(1, round(1.0 / (arm_rate(scene) * world.dt)))
    onsets, events, truth_t, costs, active = [], [], [], [], []
    use_tau = pipe.source == "joint_torques"
    for _ in range(int(round(duration / world.dt))):
        s = world.step()
        if world.steps % every:
            continue
        main = max(s.contacts, key=lambda c: float(np.linalg.norm(c.force)), default=None)
        if main is not None:
            truth_t.append(s.t)
        current = world.read_current(s)
        tau_j = world.read_joint_torques(s) if use_tau else None  # the sensors' reading: offsets, noise
        t_ns = int(round(s.t * 1e9))
        c0 = time.thread_time()  # CPU time: this host's other load does not count
        res = pipe.process_joints(t_ns, s.q, s.qd, current=current, tau_j=tau_j)
        costs.append(time.thread_time() - c0)
        active.append(res.detection.active)
        judge_events(res.events, s.t, main, onsets, events)
    return {"onsets": onsets, "events": events, "truth_t": np.array(truth_t), "cost_s": np.array(costs),
            "active": np.array(active, dtype=bool), "invalid": pipe.invalid_frames}


def judge_events(frame_events, t: float, main, onsets: list, events: list) -> None:
    """One frame's events against the world's strongest contact ``main`` (None: none) at time ``t`` (s):
    its onsets into ``onsets`` as (t, link); its estimates in contact into ``events``, each with its link,
    flags, point error (mm) and whether the truth lies within its 95 % ellipsoid."""
    for e in frame_events:
        if e.kind == "onset":
            onsets.append((t, e.link))
        if e.kind in ("onset", "update") and main is not None and "no_estimate" not in e.flags:
            err = np.asarray(e.point) - main.point
            std = np.maximum(np.asarray(e.point_std), 1e-9)
            events.append({"t": t, "link": e.link, "true_link": main.link, "flags": list(e.flags),
                           "err_mm": float(np.linalg.norm(err)) * 1e3,
                           "covered": bool(np.sum((err / std) ** 2) <= CHI2_3_95),
                           "std_mm": float(np.linalg.norm(std)) * 1e3,
                           "force": float(np.linalg.norm(main.force)), "probability": e.probability})


def oracle_corrections(scene: Scene, world_scene: Scene) -> Corrections:
    """What a perfect identification would give (an upper bound of ``calibration/``'s): the drawn arm's own
    torque constants, Coulomb and viscous friction and link inertials. Left out, as identification would
    leave them: its Stribeck excess at standstill and every noise."""
    w, r = world_scene.world, scene.robot
    joints = {"torque_constant": w.torque_constant if w.torque_constant is not None else r.torque_constant,
              "friction_viscous": w.friction_viscous if w.friction_viscous is not None else r.friction_viscous,
              "friction_coulomb": w.friction_coulomb if w.friction_coulomb is not None else r.friction_coulomb}
    true = compile_true_arm(world_scene, true_arm_spec(world_scene, shell="none"))
    model = ArmModel(scene).model
    inertials = {}
    for body in w.inertials:
        bm, bt = model.body(body).id, true.body(body).id
        inertials[body] = body_params(true, bt) - body_params(model, bm)
    return Corrections(joints={k: np.asarray(v, dtype=float) for k, v in joints.items()}, inertials=inertials)


def evaluate(scene_name: str, reality: str = "ideal", *, free_s: float = 60.0, n_probes: int = 40, seed: int = 0,
             sensing: tuple[str, ...] = ("currents",), settings: PipelineSettings | None = None,
             distal: bool = False, oracle: bool = False) -> dict[str, Any]:
    """Free run and probed run (``distal``: probes on the last three touchable links only; ``oracle``: the
    pipeline corrected by :func:`oracle_corrections`)."""
    scene = load_scene(scene_name).with_sensing(list(sensing))
    world_scene = with_reality(scene, reality, seed)
    if oracle:
        settings = (settings or PipelineSettings()).replace(corrections=oracle_corrections(scene, world_scene))
    model = ArmModel(scene)
    traj = sweep(scene)
    free = run_world(scene, world_scene, ScenarioSetup(traj), free_s, seed, settings) if free_s > 0 else None
    rng = np.random.default_rng(seed)
    last3 = frozenset(t.link for t in scene.touchable[-3:])
    pr = probes(scene, model, traj, n_probes, rng, links=last3 if distal else None)
    probed = run_world(scene, world_scene, ScenarioSetup(traj, probes=pr), pr[-1].t_end + 0.5, seed + 1, settings)
    return summarize(scene, pr, free, probed) | {"scene": scene_name, "reality": reality, "sensing": list(sensing),
                                                   "free_s": free_s, "probes": n_probes, "seed": seed,
                                                   "distal": distal, "oracle": oracle}


def summarize(scene: Scene, pr: tuple[Probe, ...], free: dict | None, probed: dict) -> dict[str, Any]:
    last3 = {t.link for t in scene.touchable[-3:]}
    model = ArmModel(scene)
    # a link no joint moves (the base) puts no torque on any joint: no joint signal can see it
    seen = {t.link for t in scene.touchable if model.moving_joints(t.link).any()}
    out: dict[str, Any] = {}
    if free is not None:
        minutes = len(free["cost_s"]) / arm_rate(scene) / 60.0
        out["false_alarms"] = len(free["onsets"])
        out["false_alarms_per_min"] = len(free["onsets"]) / minutes if minutes else math.nan
        out["free_minutes"] = minutes
    truth_t = probed["truth_t"]
    stray = [t for t, _ in probed["onsets"] if truth_t.size == 0 or np.min(np.abs(truth_t - t)) > 0.1]
    out["false_alarms_probed_run"] = len(stray)
    bands: dict[str, list] = {}
    per_link: dict[str, dict[str, list]] = {}
    d2_true = _probe_d2(pr, free, probed)
    tested = probed.get("tested")
    out["probes"] = []
    for p, d2 in zip(pr, d2_true, strict=True):
        hit = [t for t, _ in probed["onsets"] if p.t_start <= t <= p.t_end + 0.05]
        delay = (hit[0] - p.t_start) * 1e3 if hit else math.nan
        band = next(f"{lo:g}-{hi:g} N" for lo, hi in BANDS if lo <= p.magnitude <= hi)
        threshold = None if d2 is None else link_threshold(model, p.link, **tested)
        able = bool(d2 > threshold) if d2 is not None else None
        row = per_link.setdefault(p.link, {"detected": [], "events": [], "undetectable": [], "undetectable_50": []})
        row["detected"].append(bool(hit))
        row["undetectable"].append(able is False)
        row["undetectable_50"].append(able is False and p.magnitude >= 50.0)
        out["probes"].append({"link": p.link, "force_n": p.magnitude, "band": band, "detected": bool(hit),
                              "delay_ms": delay, "d2_true": d2, "threshold": threshold, "detectable": able})
        bands.setdefault(band, []).append((bool(hit), delay, p.link in seen, able))
    out["detection"] = {b: _band(v) for b, v in sorted(bands.items())}
    if free is not None and free.get("floor") is not None and tested is not None:
        out["noise_floor_std_by_speed"] = {"speed_edges_rad_s": SPEED_EDGES.tolist(), "std": free["floor"].table()}
    ev = probed["events"]
    for e in ev:
        per_link.setdefault(e["true_link"], {"detected": [], "events": [], "undetectable": [],
                                             "undetectable_50": []})["events"].append(e)
    out["per_link"] = {link: {"probes": len(v["detected"]), "detected": _share(v["detected"]),
                              "undetectable": int(sum(v["undetectable"])),
                              "undetectable_50n": int(sum(v["undetectable_50"])),
                              "events": len(v["events"]),
                              "right": _share([e["link"] == e["true_link"] for e in v["events"]]),
                              "ambiguous": _share([("ambiguous" in e["flags"]) for e in v["events"]]),
                              "error_mm_median": _pct([e["err_mm"] for e in v["events"]], 50)}
                       for link, v in per_link.items()}
    out["unseen_links"] = sorted({t.link for t in scene.touchable} - seen)
    unflagged = [e for e in ev if "ambiguous" not in e["flags"]]
    distal = [e for e in ev if e["true_link"] in last3]
    distal_u = [e for e in distal if "ambiguous" not in e["flags"]]
    out["events"] = len(ev)
    out["ambiguous_share"] = _share([("ambiguous" in e["flags"]) for e in ev])
    out["link_right_unflagged"] = _share([e["link"] == e["true_link"] for e in unflagged])
    out["link_right_all"] = _share([e["link"] == e["true_link"] for e in ev])
    out["last3_error_mm"] = {"median": _pct([e["err_mm"] for e in distal], 50),
                             "p95": _pct([e["err_mm"] for e in distal], 95), "n": len(distal)}
    out["last3_unflagged_error_mm"] = {"median": _pct([e["err_mm"] for e in distal_u], 50),
                                       "p95": _pct([e["err_mm"] for e in distal_u], 95), "n": len(distal_u)}
    out["last3_ambiguous_share"] = _share([("ambiguous" in e["flags"]) for e in distal])
    out["coverage95_unflagged"] = _share([e["covered"] for e in unflagged])
    out["frame_cost_us"] = frame_costs(probed)
    return out


def _band(v: list[tuple[bool, float, bool, bool | None]]) -> dict[str, Any]:
    """A band's detection from its probes (detected, delay ms, on a link some joint moves, detectable) in
    three tiers, each apart: every probe (``*_all``: the base's too), the probes on links some joint moves
    (the unmarked figures; ``unseen_links`` apart: no joint signal can see those), and the detectable ones
    alone (``*_detectable``, ``bench/detectable.py``: the true contact stands out of the free run's
    measured floor). ``n_undetectable``: the band's probes that are not detectable, the base's included."""
    def within(x) -> bool:
        return x[0] and x[1] <= 20.0

    seen = [x for x in v if x[2]]
    able = [x for x in seen if x[3]]
    return {"n_all": len(v), "detected_all": _share([x[0] for x in v]),
            "within_20ms_all": _share([within(x) for x in v]),
            "n": len(seen), "detected": _share([x[0] for x in seen]), "within_20ms": _share([within(x) for x in seen]),
            "delay_ms_median": _pct([x[1] for x in seen if x[0]], 50),
            "n_detectable": len(able), "detected_detectable": _share([x[0] for x in able]),
            "within_20ms_detectable": _share([within(x) for x in able]),
            "n_undetectable": sum(1 for x in v if x[3] is False)}


def _probe_d2(pr: tuple[Probe, ...], free: dict | None, probed: dict) -> list[float | None]:
    """Each probe's true d2 against the free run's floor within the acceptance's window
    (``bench/detectable.py``); None each where the runs carry no floor or truth."""
    floor = None if free is None else free.get("floor")
    if floor is None or "truth" not in probed or "tested" not in probed:
        return [None] * len(pr)
    return [probe_d2(probed["truth"], floor, p.t_start) for p in pr]


def frame_costs(run: dict[str, Any]) -> dict[str, dict[str, float]]:
    """process_joints' CPU time per frame (us): median, p99, max, apart for frames without and in contact."""
    out = {}
    for name, mask in (("free", ~run["active"]), ("in_contact", run["active"])):
        c = run["cost_s"][mask] * 1e6
        out[name] = ({"frames": int(c.size), "median": float(np.median(c)), "p99": float(np.percentile(c, 99)),
                      "max": float(c.max())} if c.size else {"frames": 0})
    return out


def _share(flags: list[bool]) -> float:
    return float(np.mean(flags)) if flags else math.nan


def _pct(values, q: float) -> float:
    return float(np.percentile(values, q)) if len(values) else math.nan


def time_frames(scene_name: str, *, n_probes: int = 8, seed: int = 0, sensing: tuple[str, ...] = ("currents",),
                settings: PipelineSettings | None = None, repeats: int = 3) -> dict[str, Any]:
    """process_joints' CPU time per frame (``ftc bench``-style): the world's joint samples recorded first
    (sweep and distal probes), then the pipeline timed alone over them, ``repeats`` times (the fastest
    pass per frame: what the code costs, not this host's other load)."""
    scene = load_scene(scene_name).with_sensing(list(sensing))
    traj = sweep(scene)
    last3 = frozenset(t.link for t in scene.touchable[-3:])
    pr = probes(scene, ArmModel(scene), traj, n_probes, np.random.default_rng(seed), links=last3)
    world = World(scene, ScenarioSetup(traj, probes=pr), seed=seed)
    every = max(1, round(1.0 / (arm_rate(scene) * world.dt)))
    frames = []
    for _ in range(int(round((pr[-1].t_end + 0.3) / world.dt))):
        s = world.step()
        if world.steps % every == 0:
            tau_j = world.read_joint_torques(s) if s.tau_j is not None else None
            frames.append((int(round(s.t * 1e9)), s.q, s.qd, world.read_current(s), tau_j))
    best = np.full(len(frames), np.inf)
    active = np.zeros(len(frames), dtype=bool)
    for _ in range(repeats):
        pipe = JointContactPipeline(scene, settings)
        for i, (t_ns, q, qd, current, tau_j) in enumerate(frames):
            c0 = time.thread_time()
            res = pipe.process_joints(t_ns, q, qd, current=current, tau_j=tau_j)
            best[i] = min(best[i], time.thread_time() - c0)
            active[i] = res.detection.active
    return {"scene": scene_name, "rate_hz": arm_rate(scene), **frame_costs({"cost_s": best, "active": active})}


def run(json_path: Path | None = None, scenes: tuple[str, ...] = ("ur5e",), reality: str = "ideal",
        free_s: float = 60.0, n_probes: int = 40, seed: int = 0, *, distal: bool = False, oracle: bool = False,
        settings: PipelineSettings | None = None) -> dict[str, Any]:
    """:func:`evaluate` per scene (currents only), the results as JSON at ``json_path``."""
    results = {name: evaluate(name, reality, free_s=free_s, n_probes=n_probes, seed=seed, distal=distal,
                              oracle=oracle, settings=settings) for name in scenes}
    if json_path is not None:
        json_path.write_text(json.dumps(results, indent=2))
    return results
