"""``ftc bench proprio``: contact sensing by what an arm senses (issue 37), each column one scene and one
sensing, side by side on the same bench: a typical world (a seeded draw of another arm, sensor and shell:
``sim_devices/world/reality.py``), the arm identified first from ``identify_s`` of the planned excitation
in that world (joint sensing: ``calibration/joint_ident.py``; a base F/T sensor: its free-motion fit, with
the currents' joint terms), then, driven by the samples the devices would deliver:

- a free run of every joint sweeping (``free_s``): false alarms per minute (an onset with no contact
  in the world within 0.1 s);
- a probed run over the same sweep: probes at random visible surface points (every touchable link, or
  only ``links``), pushing within 30 deg of the inward normal in force bands; per band: detected, within
  20 ms, the delay; per event in contact: link right, flagged ``ambiguous``, the point's error (median,
  p95) and 95 % coverage of its reported uncertainty over the unflagged ones.

A base F/T sensor drives the F/T pipeline at its rate (the joint state at each of its samples, tared at
rest); every other sensing drives the joint pipeline at the arm's rate. The probes of one column are the
same whichever sensing: the columns of a scene differ only in what the pipeline reads.
"""
from __future__ import annotations

import dataclasses
import fnmatch
import json
import math
import os
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rich.table import Table

from ftc_hw.app.calibration.identify import identify
from ftc_hw.app.calibration.identify_joints import identify_joints
from ftc_hw.bench.detectable import Floor, TruthVector
from ftc_hw.bench.joint import arm_rate, judge_events, probes, summarize, sweep
from ftc_hw.bench.report import table_console
from ftc_hw.calibration.free_motion import MotionData
from ftc_hw.calibration.joint_motion import JointMotionData
from ftc_hw.model import ArmModel
from ftc_hw.pipeline import ContactPipeline, Corrections, PipelineSettings, pipeline_for
from ftc_hw.scene import Scene, load_scene
from ftc_hw.sim_devices.world import ScenarioSetup, World, build_scenario, with_reality

TARE_S = 0.1  # at rest before anything moves (the sweep rests 0.5 s)


@dataclass(frozen=True)
class Column:
    scene: str
    sensing: tuple[str, ...]
    links: tuple[str, ...] | None = None  # probes on these links only (None: every touchable link)

    @property
    def name(self) -> str:
        where = f" on {'+'.join(self.links)}" if self.links else ""
        return f"{self.scene}: {' + '.join(self.sensing)}{where}"


# the columns: currents only, torques only, base F/T, base F/T + currents, flange F/T + currents;
# the last two also on the tool and wrist (the flange sensor against the base one, same bench)
COLUMNS = (
    Column("ur10e", ("currents",)),
    Column("panda", ("joint_torques",)),
    Column("ur10e-base-ft", ("base_ft",)),
    Column("ur10e-base-ft", ("base_ft", "currents")),
    Column("ur10e", ("flange_ft", "currents")),
    Column("ur10e", ("flange_ft", "currents"), ("tool",)),
    Column("ur10e-base-ft", ("base_ft", "currents"), ("tool", "wrist_3")),
)


@dataclass(frozen=True)
class Job:
    column: Column
    draw: int
    free_s: float
    n_probes: int
    identify_s: float


def identified(scene: Scene, world_scene: Scene, identify_s: float, seed: int) -> Corrections:
    """The corrections ``ftc identify --plan`` would give from ``identify_s`` of the planned excitation
    in ``world_scene`` (in this process: the samples the devices would deliver, no emulator)."""
    setup = build_scenario("excitation", scene, ArmModel(scene), seed, identify_s)
    world = World(world_scene, setup, seed=seed)
    ft = scene.sensing.ft == "base"
    every = world.steps_per_sample if ft else max(1, round(1.0 / (arm_rate(scene) * world.dt)))
    rows: dict[str, list] = {"t": [], "q": [], "qd": [], "current": [], "tau_j": [], "wrench": []}
    for _ in range(int(round(identify_s / world.dt))):
        s = world.step()
        if world.steps % every:
            continue
        rows["t"].append(s.t)
        rows["q"].append(s.q)
        rows["qd"].append(s.qd)
        rows["current"].append(world.read_current(s))
        if s.tau_j is not None:
            rows["tau_j"].append(world.read_joint_torques(s))  # the sensors' reading: offsets, noise
        if ft:
            rows["wrench"].append(world.read_sensor(s).wrench)
    a = {k: np.array(v) for k, v in rows.items() if v}
    if ft:
        cal, _ = identify(scene, [MotionData(a["t"], a["wrench"], a["q"], a["qd"], a["current"])], None, "bench")
        return dataclasses.replace(cal.corrections(scene), bias=None)  # tared at rest like every column
    motion = JointMotionData(a["t"], a["q"], a["qd"], current=a.get("current") if scene.sensing.currents else None,
                             tau_j=a.get("tau_j"))
    cal, _ = identify_joints(scene, [motion], None, "bench")
    return cal.corrections(scene)


def run_world(scene: Scene, world_scene: Scene, setup: ScenarioSetup, duration: float, seed: int,
              settings: PipelineSettings) -> dict[str, Any]:
    """The scene's pipeline over ``duration`` s of the world: onsets, events in contact with the truth,
    per-frame CPU time (s), the tested signal's free-motion floor and its truth in contact (detectable.py).
    The F/T pipeline takes each sensor sample, the joint pipeline each joint sample; the first ``TARE_S``
    (at rest) tare the F/T sensor and the joint torque sensors where not identified."""
    world = World(world_scene, setup, seed=seed)
    pipe = pipeline_for(scene, settings)
    ft_driven = isinstance(pipe, ContactPipeline)
    truth_vector = TruthVector(scene, joints=not ft_driven, ft=ft_driven or scene.sensing.ft == "flange")
    n_tested = (0 if ft_driven else scene.n_joints) + (6 if truth_vector.ft else 0)
    floor = Floor(n_tested, 0 if ft_driven else scene.n_joints)  # the tested vector's spread out of contact
    truth: list[tuple[float, np.ndarray, np.ndarray]] = []
    onsets, events, truth_t, costs, active = [], [], [], [], []
    for s, res, cost in drive(scene, world, pipe, duration, tare_torques=not _has_offsets(settings)):
        main = max(s.contacts, key=lambda c: float(np.linalg.norm(c.force)), default=None)
        if main is not None:
            truth_t.append(s.t)
            truth.append((s.t, truth_vector(s.q, s.contacts), s.qd))
        costs.append(cost)
        active.append(res.detection.active)
        if main is None:
            floor.add(res.external if ft_driven else pipe.tested, s.qd)
        judge_events(res.events, s.t, main, onsets, events)
    every = world.steps_per_sample if ft_driven else sample_every(scene, world)
    return {"onsets": onsets, "events": events, "truth_t": np.array(truth_t), "cost_s": np.array(costs),
            "active": np.array(active, dtype=bool), "rate_hz": 1.0 / (every * world.dt),
            "floor": floor if floor.frames else None, "truth": truth,
            "tested": {"joints": truth_vector.joints, "ft": truth_vector.ft,
                       "p_false": settings.detection.p_false}}


def sample_every(scene: Scene, world: World) -> int:
    """Physics steps per joint sample (the arm device's rate)."""
    return max(1, round(1.0 / (arm_rate(scene) * world.dt)))


def drive(scene: Scene, world: World, pipe, duration: float, *, tare_torques: bool = True):
    """Yield (world state, the pipeline's FrameResult, its CPU time s) for ``duration`` s of the world, at the
    samples the scene's devices would deliver: the F/T pipeline each sensor sample, the joint pipeline each
    joint sample, each sensor as read (offsets, noise: not the truth); the first ``TARE_S`` (at rest) tare
    the F/T sensor and (``tare_torques``) the joint torque sensors, and yield nothing."""
    ft_driven = isinstance(pipe, ContactPipeline)
    every = world.steps_per_sample if ft_driven else sample_every(scene, world)
    sensing = scene.sensing
    tare: list[tuple] = []
    tare_left = sensing.ft is not None or (sensing.joint_torques and tare_torques)
    for _ in range(int(round(duration / world.dt))):
        s = world.step()
        if world.steps % every:
            continue
        reading = world.read_sensor(s) if s.wrench is not None and sensing.ft else None
        wrench = reading.wrench if reading is not None else None
        current = world.read_current(s)
        tau_j = world.read_joint_torques(s) if s.tau_j is not None else None
        if tare_left:
            tare.append((wrench, s.q, tau_j))
            if s.t >= TARE_S:
                _tare(pipe, tare, s.t)
                tare_left = False
            continue
        t_ns = int(round(s.t * 1e9))
        c0 = time.thread_time()  # CPU time: this host's other load does not count
        if ft_driven:
            res = pipe.process(t_ns, wrench, s.q, s.qd, current if sensing.currents else None,
                               saturated=bool(reading.saturated.any()))
        else:
            res = pipe.process_joints(t_ns, s.q, s.qd, current=current if sensing.currents else None,
                                      tau_j=tau_j if sensing.joint_torques else None, wrench=wrench)
        yield s, res, time.thread_time() - c0


def _has_offsets(settings: PipelineSettings) -> bool:
    return "torque_offset" in (settings.corrections.joints or {})


def _tare(pipe, samples: list[tuple], t: float) -> None:
    wrenches = [w for w, _, _ in samples if w is not None]
    torques = [tj for _, _, tj in samples if tj is not None]
    w = np.mean(wrenches, axis=0) if wrenches else None
    q = np.mean([q for _, q, _ in samples], axis=0)
    t_ns = int(round(t * 1e9))
    if isinstance(pipe, ContactPipeline):
        pipe.tare(w, q, len(wrenches), t_ns)
    else:
        pipe.tare(w, q, max(len(wrenches), len(torques)), t_ns, tau_j=np.mean(torques, axis=0) if torques else None)


def run_job(job: Job) -> dict[str, Any]:
    """One column and draw: identify, then the free and the probed run."""
    col = job.column
    scene = load_scene(col.scene).with_sensing(list(col.sensing))
    world_scene = with_reality(scene, "typical", seed=job.draw)
    corrections = identified(scene, world_scene, job.identify_s, 1000 + job.draw) if job.identify_s > 0 \
        else Corrections()
    settings = PipelineSettings(corrections=corrections)
    traj = sweep(scene)
    free = run_world(scene, world_scene, ScenarioSetup(traj), job.free_s, job.draw, settings)
    rng = np.random.default_rng(job.draw)
    pr = probes(scene, ArmModel(scene), traj, job.n_probes, rng,
                links=frozenset(col.links) if col.links else None)
    probed = run_world(scene, world_scene, ScenarioSetup(traj, probes=pr), pr[-1].t_end + 0.5, job.draw + 1,
                       settings)
    rate = free["rate_hz"]
    out = summarize(scene, pr, free | {"cost_s": free["cost_s"]}, probed)
    out["free_minutes"] = len(free["cost_s"]) / rate / 60.0
    out["false_alarms_per_min"] = len(free["onsets"]) / out["free_minutes"] if out["free_minutes"] else math.nan
    return out | {"column": col.name, "draw": job.draw, "rate_hz": rate}


def combine(draws: list[dict[str, Any]]) -> dict[str, Any]:
    """A column's draws as one row: counts summed, shares and errors over the events of every draw."""
    fa = sum(d["false_alarms"] + 0 for d in draws)
    minutes = sum(d["free_minutes"] for d in draws)
    bands: dict[str, dict[str, float]] = {}
    for band in sorted({b for d in draws for b in d["detection"]}):
        rows = [d["detection"][band] for d in draws if band in d["detection"]]
        bands[band] = {"delay_ms_median": _nanmedian([r["delay_ms_median"] for r in rows]),
                       "n_undetectable": sum(r.get("n_undetectable", 0) for r in rows)}
        for tier in ("_all", "", "_detectable"):
            bands[band] |= _pooled(rows, tier)

    def mean(key: str, sub: str | None = None) -> float:
        values = [(d[key][sub] if sub else d[key]) for d in draws]
        values = [v for v in values if not (isinstance(v, float) and math.isnan(v))]
        return float(np.mean(values)) if values else math.nan

    return {"column": draws[0]["column"], "draws": len(draws), "free_minutes": minutes, "false_alarms": fa,
            "false_alarms_per_min": fa / minutes if minutes else math.nan, "detection": bands,
            "at_least_10n": _at_least(bands, 10.0),
            "link_right_unflagged": mean("link_right_unflagged"), "ambiguous_share": mean("ambiguous_share"),
            "error_mm_median": mean("last3_unflagged_error_mm", "median"),
            "error_mm_p95": mean("last3_unflagged_error_mm", "p95"),
            "all_error_mm_median": mean("last3_error_mm", "median"),
            "coverage95": mean("coverage95_unflagged"), "undetectable_per_link": _undetectable(draws),
            "per_draw": draws}


def _pooled(rows: list[dict[str, Any]], tier: str) -> dict[str, Any]:
    """A band's detection in one tier (``_band`` in ``bench/joint.py``: "_all", "" or "_detectable"), the draws'
    counts summed."""
    n_key, det_key, in_key = ("n" + tier, "detected" + tier, "within_20ms" + tier) if tier != "_detectable" else \
        ("n_detectable", "detected_detectable", "within_20ms_detectable")
    kept = [r for r in rows if r.get(n_key, 0)]
    n = sum(r[n_key] for r in kept)
    if not n:
        return {n_key: 0, det_key: math.nan, in_key: math.nan}
    return {n_key: n, det_key: sum(r[det_key] * r[n_key] for r in kept) / n,
            in_key: sum(r[in_key] * r[n_key] for r in kept) / n}


def _at_least(bands: dict[str, dict[str, Any]], low_n: float) -> dict[str, Any]:
    """Detection over the bands from ``low_n`` up, as one (the issue's "contacts of 10 N and more"), in the three
    tiers of ``_band`` (``*_all``: every probe, the base's too)."""
    rows = [v for b, v in bands.items() if float(b.split("-")[0]) >= low_n]
    out: dict[str, Any] = {}
    for tier in ("_all", "", "_detectable"):
        out |= _pooled(rows, tier)
    return out


def _undetectable(draws: list[dict[str, Any]]) -> dict[str, dict[str, int]]:
    """Per link, over the draws: probes, undetectable ones, undetectable ones of 50 N and more."""
    out: dict[str, dict[str, int]] = {}
    for d in draws:
        for link, v in d["per_link"].items():
            row = out.setdefault(link, {"probes": 0, "undetectable": 0, "undetectable_50n": 0})
            for k in row:
                row[k] += v.get(k, 0)
    return out


def run(json_path: Path | None = None, *, columns: tuple[Column, ...] = COLUMNS, draws: int = 2,
        free_s: float = 300.0, n_probes: int = 40, identify_s: float = 120.0,
        workers: int | None = None) -> dict[str, Any]:
    """Every column over ``draws`` seeded draws (``free_s`` each: 2 draws of 300 s make the 10 minutes),
    in worker processes; the table, and the results as JSON at ``json_path``."""
    jobs = [Job(c, d, free_s, n_probes, identify_s) for c in columns for d in range(draws)]
    workers = workers or max(1, min(len(jobs), os.cpu_count() or 1))
    with ProcessPoolExecutor(workers) as pool:
        done = list(pool.map(run_job, jobs))
    results = {c.name: combine([r for r in done if r["column"] == c.name]) for c in columns}
    _table(results)
    if json_path is not None:
        json_path.write_text(json.dumps({"free_s": free_s, "draws": draws, "probes": n_probes,
                                         "identify_s": identify_s, "world": "typical", "columns": results},
                                        indent=2, default=float))
    return results


def _table(results: dict[str, Any]) -> None:
    t = Table(title="contact sensing by what the arm senses (typical world, identified first)")
    # >= 50 N in three tiers, each with its count: every probe, those on links a joint moves, the detectable
    for c in ("column", "min", "false alarms /min", ">=10 N detected (all)", ">=50 N all: n, detected (in 20 ms)",
              ">=50 N on moving links: n, detected (in 20 ms)", ">=50 N detectable: n, detected (in 20 ms)",
              "undetectable (>=50 N) per link", "10-25 N detected",
              "delay ms", "link right", "err mm med / p95 (last 3)", "ambiguous", "coverage 95"):
        t.add_column(c, justify="left" if c == "column" else "right")

    def pct(x: float) -> str:
        return "-" if x is None or math.isnan(x) else f"{100 * x:.0f} %"

    def num(x: float, fmt: str = "{:.1f}") -> str:
        return "-" if x is None or math.isnan(x) else fmt.format(x)

    for r in results.values():
        big = r["detection"].get("50-100 N", {})
        mid = r["detection"].get("10-25 N", {})
        t.add_row(r["column"], num(r["free_minutes"]), num(r["false_alarms_per_min"], "{:.2f}"),
                  pct(r["at_least_10n"]["detected_all"]),
                  *(f"{big.get('n' + tier, 0)}, {pct(big.get('detected' + tier, math.nan))} "
                    f"({pct(big.get('within_20ms' + tier, math.nan))})" for tier in ("_all", "", "_detectable")),
                  ", ".join(f"{link} {v['undetectable']} ({v['undetectable_50n']})"
                            for link, v in r["undetectable_per_link"].items() if v["undetectable"]) or "-",
                  pct(mid.get("detected", math.nan)), num(big.get("delay_ms_median", math.nan)),
                  pct(r["link_right_unflagged"]),
                  f"{num(r['error_mm_median'])} / {num(r['error_mm_p95'])}", pct(r["ambiguous_share"]),
                  pct(r["coverage95"]))
    table_console().print(t)


def select(patterns: list[str] | None) -> tuple[Column, ...]:
    """The columns whose name matches any of ``patterns`` (globs; None: all); a ValueError names the
    pattern that matches none."""
    if not patterns:
        return COLUMNS
    out = []
    for p in patterns:
        hit = [c for c in COLUMNS if fnmatch.fnmatch(c.name, p)]
        if not hit:
            raise ValueError(f"no column matches {p!r} (columns: {'; '.join(c.name for c in COLUMNS)})")
        out += [c for c in hit if c not in out]
    return tuple(out)


def _nanmedian(values: list[float]) -> float:
    kept = [v for v in values if not math.isnan(v)]
    return float(np.median(kept)) if kept else math.nan
