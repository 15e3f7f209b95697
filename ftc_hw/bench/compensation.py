"""``ftc bench compensation``: what each compensation level costs and what leaving terms out costs.

For each scene and sweep speed the world runs two scenarios, ``sweep`` (free motion) and
``sweep-with-collision``, and records what the devices would deliver: the F/T readings at the
sensor rate and the joint state (q, qd, motor currents) at the arm device's rate, interpolated at the
F/T timestamps as the bus does. The pipeline (compensation at the given level, detection,
localization) then runs over the recording for each level, tared while the arm rests before the
sweep starts. Figures: external-force RMS in free motion, false alarms per minute, detection delay,
localization error while moving, and the cost per frame of the whole pipeline.
"""
from __future__ import annotations

import json
import math
import platform
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rich.table import Table

from ftc_hw.bench.report import table_console
from ftc_hw.devices.registry import role_of
from ftc_hw.model import ArmModel
from ftc_hw.pipeline import ContactPipeline, PipelineSettings
from ftc_hw.scene import COMPENSATION_LEVELS, Scene, builtin_names, load_scene
from ftc_hw.sim_devices.world import World, with_reality
from ftc_hw.sim_devices.world.scenarios import SCENARIOS

SPEEDS = (0.5, 1.0, 2.0)
TARE_FROM_S, TARE_S = 0.15, 0.1  # inside the sweeps' initial rest (SWEEP_REST_S = 0.3 s)


@dataclass
class Recording:
    t: np.ndarray  # (N,) s, F/T sample times
    wrench: np.ndarray  # (N, 6) device readings
    saturated: np.ndarray  # (N,)
    q: np.ndarray  # (N, n) joint state interpolated at the F/T times
    qd: np.ndarray
    current: np.ndarray
    contact: np.ndarray  # (N,) truth
    point: np.ndarray  # (N, 3) truth (strongest contact), zeros when none
    link: list
    force: np.ndarray | None = None  # (N,) N, truth: the strongest contact's force magnitude


def arm_rate(scene: Scene) -> float:
    for d in scene.devices:
        if role_of(d.kind) == "arm":
            return float(d.params.get("frequency", 500.0 if d.kind == "ur-rtde" else 200.0))
    return scene.sensor.rate_hz


def record(scene: Scene, scenario: str, duration: float, speed: float, seed: int,
           world_scene: Scene | None = None) -> Recording:
    """What the devices would deliver from ``scenario`` (built on ``scene``'s model) in a world of
    ``world_scene`` (a reality drawn from ``scene``; default: ``scene``, the ideal world)."""
    model = ArmModel(scene)
    rng = np.random.default_rng(seed)
    params = {"speed": speed} if scenario.startswith("sweep") else {}
    setup = SCENARIOS[scenario].build(scene, model, rng, duration, **params)
    world = World(world_scene or scene, setup, seed=seed)
    joint_every = max(1, round(1.0 / (arm_rate(scene) * world.dt)))
    jt, jq, jqd, jcur = [], [], [], []
    ft_t, ft_w, ft_sat, truth_c, truth_p, truth_l, truth_f = [], [], [], [], [], [], []
    n_steps = int(round(duration / world.dt))
    for _ in range(n_steps):
        s = world.step()
        if world.steps % joint_every == 0:
            jt.append(s.t)
            jq.append(s.q)
            jqd.append(s.qd)
            jcur.append(world.read_current(s))
        if world.steps % world.steps_per_sample == 0:
            r = world.read_sensor(s)
            ft_t.append(s.t)
            ft_w.append(r.wrench)
            ft_sat.append(bool(r.saturated.any()))
            main = max(s.contacts, key=lambda c: float(np.linalg.norm(c.force)), default=None)
            truth_c.append(main is not None)
            truth_p.append(main.point if main is not None else np.zeros(3))
            truth_l.append(main.link if main is not None else None)
            truth_f.append(float(np.linalg.norm(main.force)) if main is not None else 0.0)
    t = np.array(ft_t)
    jt_a = np.array(jt)

    def interp(values):
        v = np.array(values)
        return np.stack([np.interp(t, jt_a, v[:, j]) for j in range(v.shape[1])], axis=1)

    return Recording(t, np.array(ft_w), np.array(ft_sat), interp(jq), interp(jqd), interp(jcur),
                     np.array(truth_c), np.array(truth_p), truth_l, np.array(truth_f))


def evaluate(scene: Scene, rec: Recording, level: str) -> dict:
    pipe = ContactPipeline(scene, PipelineSettings().with_level(level))
    # tare on the settled arm, in the rest the sweeps begin with
    i0, i1 = np.searchsorted(rec.t, [TARE_FROM_S, TARE_FROM_S + TARE_S])
    pipe.motion.compensator.tare(rec.wrench[i0:i1].mean(axis=0), rec.q[i0:i1].mean(axis=0), np.zeros(scene.n_joints),
                          np.zeros(scene.n_joints))
    n_tare = i1
    onsets, costs, pos_err, free_force = [], [], [], []
    for i in range(n_tare, len(rec.t)):
        t_ns = int(round(rec.t[i] * 1e9))
        c0 = time.perf_counter_ns()
        r = pipe.process(t_ns, rec.wrench[i], rec.q[i], rec.qd[i], rec.current[i], saturated=bool(rec.saturated[i]))
        costs.append((time.perf_counter_ns() - c0) / 1e3)
        if not rec.contact[i]:
            free_force.append(float(np.linalg.norm(r.external[:3])))
        for e in r.events:
            if e.kind == "onset":
                onsets.append((i, e.t_host_ns))
        if r.detection.active and rec.contact[i] and r.estimate is not None and r.estimate.contact:
            pos_err.append(float(np.linalg.norm(r.estimate.point - rec.point[i])) * 1e3)
    # true contact episodes: runs of contact samples (gaps under 20 ms merged)
    episodes = _episodes(rec.t, rec.contact, merge_s=0.02)
    delays, false_alarms = [], 0
    for i, _t_onset in onsets:
        t_emit = rec.t[i]
        hit = next((ep for ep in episodes if ep[0] - 0.001 <= t_emit <= ep[1] + 0.02), None)
        if hit is None:
            false_alarms += 1
    for start, end in episodes:
        first = next((rec.t[i] for i, _ in onsets if start - 0.001 <= rec.t[i] <= end), None)
        if first is not None:
            delays.append((first - start) * 1e3)
    free_minutes = (1.0 - rec.contact.mean()) * (rec.t[-1] - rec.t[0]) / 60.0
    costs_a = np.array(costs)
    return {
        "free_motion_rms_N": float(np.sqrt(np.mean(np.square(free_force)))) if free_force else math.nan,
        "false_alarms": false_alarms,
        "false_alarms_per_min": false_alarms / free_minutes if free_minutes > 0 else math.nan,
        "contacts": len(episodes), "detected": len(delays),
        "detect_delay_ms_median": float(np.median(delays)) if delays else math.nan,
        "detect_delay_ms_max": float(np.max(delays)) if delays else math.nan,
        "pos_err_mm_median": float(np.median(pos_err)) if pos_err else math.nan,
        "cost_us_median": float(np.median(costs_a)), "cost_us_p99": float(np.percentile(costs_a, 99)),
    }


def _episodes(t: np.ndarray, contact: np.ndarray, merge_s: float) -> list[tuple[float, float]]:
    out: list[list[float]] = []
    for ti, c in zip(t, contact, strict=True):
        if not c:
            continue
        if out and ti - out[-1][1] <= merge_s:
            out[-1][1] = ti
        else:
            out.append([ti, ti])
    return [(a, b) for a, b in out]


def run(json_path: Path | None = None, plot_path: Path | None = None, minutes: float = 1.0, seed: int = 0,
        scenes: list[str] | None = None, speeds: tuple[float, ...] = SPEEDS, reality: str = "typical") -> dict:
    """``reality``: the world the recordings come from (one seeded draw: ``seed``)."""

    console = table_console()
    results: dict = {}
    for name in scenes or builtin_names():
        scene = load_scene(name)
        world = with_reality(scene, reality, seed)
        per_level: dict[str, dict] = {level: {"runs": []} for level in COMPENSATION_LEVELS}
        for speed in speeds:
            free = record(scene, "sweep", minutes * 60.0, speed, seed, world)
            hits = record(scene, "sweep-with-collision", minutes * 60.0, speed, seed, world)
            for level in COMPENSATION_LEVELS:
                a = evaluate(scene, free, level)
                b = evaluate(scene, hits, level)
                per_level[level]["runs"].append({"speed": speed, "free": a, "collision": b})
        results[name] = {level: _summarize(v["runs"]) | {"runs": v["runs"]} for level, v in per_level.items()}
    results["meta"] = {"minutes_per_scenario": minutes, "speeds": list(speeds), "seed": seed, "reality": reality,
                       "python": platform.python_version(), "cpus": __import__("os").cpu_count()}
    table = Table(title=f"compensation levels ({minutes:g} simulated min per scenario and speed x {list(speeds)}; "
                        f"world: {reality}, seed {seed})")
    for c in ("scene", "level", "free-motion RMS N", "false alarms/min", "detect delay ms (med)", "detected",
              "pos err mm (med)", "cost us med", "cost us p99"):
        table.add_column(c, justify="left" if c in ("scene", "level") else "right")
    for name, per in results.items():
        if name == "meta":
            continue
        for level in COMPENSATION_LEVELS:
            r = per[level]
            table.add_row(name, level, f"{r['free_motion_rms_N']:.3g}", f"{r['false_alarms_per_min']:.3g}",
                          f"{r['detect_delay_ms_median']:.3g}", f"{r['detected']}/{r['contacts']}",
                          f"{r['pos_err_mm_median']:.3g}", f"{r['cost_us_median']:.1f}", f"{r['cost_us_p99']:.1f}")
    console.print(table)
    if json_path is not None:
        json_path.write_text(json.dumps(results, indent=2))
    if plot_path is not None:
        _plot(results, plot_path)
    return results


def _summarize(runs: list[dict]) -> dict:
    free = [r["free"] for r in runs]
    col = [r["collision"] for r in runs]
    alarms = sum(f["false_alarms"] for f in free + col)
    rate = float(np.mean([f["false_alarms_per_min"] for f in free + col]))
    return {
        "free_motion_rms_N": float(np.sqrt(np.mean([f["free_motion_rms_N"] ** 2 for f in free]))),
        "false_alarms": alarms,
        "false_alarms_per_min": rate,
        "detect_delay_ms_median": _nanmedian([c["detect_delay_ms_median"] for c in col]),
        "contacts": int(sum(c["contacts"] for c in col)), "detected": int(sum(c["detected"] for c in col)),
        "pos_err_mm_median": _nanmedian([c["pos_err_mm_median"] for c in col]),
        "cost_us_median": float(np.median([c["cost_us_median"] for c in free + col])),
        "cost_us_p99": float(np.max([c["cost_us_p99"] for c in free + col])),
    }


def _nanmedian(values: list[float]) -> float:
    """The median of the finite values; NaN (nothing detected at this level) without numpy's warning."""
    finite = [v for v in values if math.isfinite(v)]
    return float(np.median(finite)) if finite else math.nan


def _plot(results: dict, path: Path) -> None:
    import matplotlib  # lazy: matplotlib only for --plot

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: matplotlib only for --plot

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for name, per in results.items():
        if name == "meta":
            continue
        xs = [per[lv]["cost_us_median"] for lv in COMPENSATION_LEVELS]
        ys = [max(per[lv]["free_motion_rms_N"], 1e-3) for lv in COMPENSATION_LEVELS]
        ax.plot(xs, ys, "o-", label=name)
        for lv, x, y in zip(COMPENSATION_LEVELS, xs, ys, strict=True):
            ax.annotate(lv, (x, y), fontsize=7, textcoords="offset points", xytext=(4, 4))
    ax.set_yscale("log")
    ax.set_xlabel("pipeline cost per frame, median (us)")
    ax.set_ylabel("external-force RMS in free motion (N)")
    ax.set_title("ftc bench compensation: error against cost")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
