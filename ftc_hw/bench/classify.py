"""``ftc bench classify``: contact classification (issue 39) on every arm scene, typical world.

Per scene and seeded draw of a typical world (``sim_devices/world/reality.py``, not identified: tared at
rest), the scene's pipeline (``pipeline_for``: a base F/T sensor's, else the joint signals'; compensated at
the dynamics level: every contact here moves the arm) is driven by the samples its devices would deliver
while the world plays ``count`` scripted contacts of each kind (``sim_devices/world/contact_kinds.py``:
clamping against a fixture, a hand guiding the arm, impacts at 0.15 / 0.3 / 0.5 m/s). Each planned contact
is judged by the contact the pipeline reported in its window (the strongest, when it reported several), at
its offset (the final class):

- ``clamping`` right: ``quasi_static`` and ``impact`` (accidental);
- ``impact`` right: ``transient`` and ``impact``;
- ``guidance`` right: ``guidance`` and ``transient`` (not clamped: the hand may let go);
- a contact not reported, or reported only after its window, is wrong (``missed``).

Also: the share whose provisional class at onset already named the right intent; and the effective mass the
events carry (judged against the built-in body limits, as the monitor does: ``ftc_hw/pipeline/limits.py``)
against the world's true arm's at the true contact along the true normal (``true_mass.py``), over the settled
updates (on the true link, the force within 10 % of the truth's and >= 10 N) whose true mass is below
``HEAVY_KG``.

With ``identify_s`` > 0 the arm is identified first from that long of the planned excitation in the same world
(as ``ftc bench proprio`` and ``ftc demo`` do: ``proprio.identified``), else only tared at rest.
"""
from __future__ import annotations

import json
import math
import os
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
from rich.table import Table

from ftc_hw.bench.proprio import drive, identified
from ftc_hw.bench.report import table_console
from ftc_hw.bench.true_mass import true_mass, true_normal
from ftc_hw.model import ArmModel
from ftc_hw.pipeline import Corrections, PipelineSettings, pipeline_for
from ftc_hw.pipeline.limits import LimitAssessor
from ftc_hw.scene import Scene, load_scene
from ftc_hw.scene.limits import builtin_limits
from ftc_hw.sim_devices.world import World, with_reality
from ftc_hw.sim_devices.world.contact_kinds import (
    CONTACT_KINDS,
    EXPECTED_CLASS,
    PlannedContact,
    plan_contacts,
    run_length,
)

# every arm scene (`ftc scenes`), by what it senses: base F/T, motor currents (+ a flange F/T), joint torques
SCENES = ("leng2016", "ur5e", "ur5e-netft", "dxl-arm", "ur10e-base-ft", "ur10e", "ur16e", "ur3e", "panda", "fr3")
RIGHT = EXPECTED_CLASS
WINDOW_AFTER_S = 0.3  # an onset up to this long after the planned window still belongs to it
HEAVY_KG = 1000.0  # a true mass above this (a point near a joint's axis) is left out of the mass's figures:
# the permissible speed then hardly depends on it (docs/limits.md)


@dataclass(frozen=True)
class Job:
    scene: str
    draw: int
    count: int
    identify_s: float = 0.0


@dataclass(frozen=True)
class Run:
    plan: tuple[PlannedContact, ...]
    events: list  # every contact event the pipeline reported (world time), judged against the built-in limits
    masses: list[dict[str, Any]]  # per settled update: its kind, the event's effective mass and the true one


def run_world(scene: Scene, world_scene: Scene, seed: int, count: int,
              settings: PipelineSettings | None = None) -> Run:
    """The scripted contacts' plan, every contact event the scene's pipeline reported (with its world time)
    and the effective masses of the settled ones against the truth."""
    setup, plan = plan_contacts(scene, ArmModel(scene), np.random.default_rng(seed), CONTACT_KINDS, count)
    world = World(world_scene, setup, seed=seed)
    # every scripted contact moves the arm: a scene compensated for gravity only (its arm's inertial loads read
    # as contact) is run at the dynamics level
    settings = (settings or PipelineSettings()).with_level("dynamics")
    pipe = pipeline_for(scene, settings)
    assessor = LimitAssessor(scene, settings, builtin_limits())
    links = set(assessor.arm.link_names)
    scratch = mujoco.MjData(world.model)  # the true arm posed for its mass, apart from the world's own data
    events: list = []
    masses: list[dict[str, Any]] = []
    for s, res, _ in drive(scene, world, pipe, run_length(plan)):
        assessor.observe(int(round(s.t * 1e9)), s.q, s.qd)
        judged = assessor.judge(res.events)
        events += judged
        masses += [m for ev in judged if (m := _mass_row(world, s, ev, links, scratch)) is not None]
    return Run(plan, events, masses)


def _mass_row(world: World, state, ev, links: set[str], scratch: mujoco.MjData) -> dict[str, Any] | None:
    """A settled update's effective mass against the true arm's at the true contact (None: not settled)."""
    if ev.kind != "update" or ev.limits is None or not state.contacts:
        return None
    c = max(state.contacts, key=lambda c: float(np.linalg.norm(c.force)))
    true_force = float(np.linalg.norm(c.force))
    if c.link != ev.link or true_force < 10.0 or abs(float(np.linalg.norm(ev.force)) - true_force) > 0.1 * true_force:
        return None
    truth = true_mass(world, state, c, true_normal(world, c, links), scratch)
    return {"kind": c.label, "mass": ev.limits.effective_mass_kg, "true": truth}


def judge(plan: tuple[PlannedContact, ...], events: list) -> list[dict[str, Any]]:
    """Each planned contact against the contact the pipeline reported in its window (the strongest)."""
    by_id: dict[int, dict[str, Any]] = {}
    for e in events:
        c = by_id.setdefault(e.contact_id, {})
        c.setdefault(e.kind, e)
        if e.kind == "offset":
            c["offset"] = e
    out = []
    for p in plan:
        inside = [c for c in by_id.values() if "onset" in c and "offset" in c
                  and p.t_start <= c["onset"].t_host_ns * 1e-9 <= p.t_end + WINDOW_AFTER_S]
        row: dict[str, Any] = {"kind": p.kind, "link": p.link, "speed": p.speed, "force": p.force,
                               "reported": len(inside)}
        if inside:
            c = max(inside, key=lambda c: c["offset"].peak_force)
            final, onset = c["offset"], c["onset"]
            want = RIGHT[p.kind]
            row |= {"contact_class": final.contact_class, "intent": final.intent,
                    "p_quasi_static": final.p_quasi_static, "p_guidance": final.p_guidance,
                    "duration_s": final.duration_s, "peak_n": final.peak_force,
                    "features": dict(final.class_features),
                    "right": (final.contact_class, final.intent) == want,
                    "onset_intent_right": onset.intent == want[1]}
        else:
            row |= {"right": False, "onset_intent_right": False}
        out.append(row)
    return out


def run_job(job: Job) -> dict[str, Any]:
    scene = load_scene(job.scene)
    world_scene = with_reality(scene, "typical", seed=job.draw)
    corrections = identified(scene, world_scene, job.identify_s, 1000 + job.draw) if job.identify_s > 0 \
        else Corrections()
    try:
        run = run_world(scene, world_scene, 100 + job.draw, job.count, PipelineSettings(corrections=corrections))
    except RuntimeError as exc:  # no scripted contact could be planned: said in the results, the others go on
        return {"scene": job.scene, "draw": job.draw, "contacts": [], "masses": [], "error": str(exc)}
    return {"scene": job.scene, "draw": job.draw, "contacts": judge(run.plan, run.events), "masses": run.masses}


def summarize(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Per kind: n, right share, missed, onset intent right, the final class's probability (median)."""
    out = {}
    for kind in CONTACT_KINDS:
        r = [x for x in rows if x["kind"] == kind]
        reported = [x for x in r if x["reported"]]
        p_named = [max(x["p_quasi_static"], 1 - x["p_quasi_static"]) for x in reported]
        out[kind] = {"n": len(r), "right": _share([x["right"] for x in r]),
                     "missed": sum(1 for x in r if not x["reported"]),
                     "onset_intent_right": _share([x["onset_intent_right"] for x in r]),
                     "p_median": float(np.median(p_named)) if p_named else math.nan}
    return out


def mass_summary(masses: list[dict[str, Any]]) -> dict[str, Any]:
    """The events' effective masses against the truth, per kind and all: n (below ``HEAVY_KG``), within 10 %
    and 25 %, the median relative error; ``heavy``: left out (true mass above ``HEAVY_KG``)."""
    out: dict[str, Any] = {}
    for kind in (*CONTACT_KINDS, "all"):
        rows = [m for m in masses if kind in ("all", m["kind"])]
        err = np.array([abs(m["mass"] / m["true"] - 1.0) for m in rows if m["true"] < HEAVY_KG])
        out[kind] = {"n": int(err.size), "heavy": len(rows) - int(err.size),
                     "within_10": float(np.mean(err < 0.10)) if err.size else math.nan,
                     "within_25": float(np.mean(err < 0.25)) if err.size else math.nan,
                     "median": float(np.median(err)) if err.size else math.nan}
    return out


def run(json_path: Path | None = None, *, scenes: tuple[str, ...] = SCENES, draws: int = 1, count: int = 20,
        workers: int | None = None, identify_s: float = 60.0) -> dict[str, Any]:
    """Every scene over ``draws`` typical draws, ``count`` contacts of each kind per draw (the arm identified
    first from ``identify_s`` of excitation; 0: tared only), in worker processes; the table, and the results as
    JSON at ``json_path`` (rewritten as each scene and draw is done: a long run's partial figures are kept)."""
    jobs = [Job(s, d, count, identify_s) for d in range(draws) for s in scenes]  # every scene's first draw first
    workers = workers or max(1, min(len(jobs), os.cpu_count() or 1))
    done: list[dict[str, Any]] = []
    with ProcessPoolExecutor(workers) as pool:
        for future in as_completed([pool.submit(run_job, job) for job in jobs]):
            done.append(future.result())
            if json_path is not None:
                _write(json_path, _collect(done, scenes), draws, count, identify_s, len(done) == len(jobs))
    results = _collect(done, scenes)
    _table(results)
    return results


def _collect(done: list[dict[str, Any]], scenes: tuple[str, ...]) -> dict[str, Any]:
    results = {}
    for s in scenes:
        mine = sorted((d for d in done if d["scene"] == s), key=lambda d: d["draw"])
        if not mine:
            continue
        rows = [c | {"draw": d["draw"]} for d in mine for c in d["contacts"]]
        masses = [m for d in mine for m in d["masses"]]
        errors = [d["error"] for d in mine if "error" in d]
        results[s] = {"draws": [d["draw"] for d in mine], "kinds": summarize(rows), "mass": mass_summary(masses),
                      "contacts": rows, "masses": masses} | ({"errors": errors} if errors else {})
    return results


def _write(path: Path, results: dict[str, Any], draws: int, count: int, identify_s: float, complete: bool) -> None:
    path.write_text(json.dumps({"world": "typical", "draws": draws, "count": count, "identify_s": identify_s,
                               "complete": complete, "scenes": results}, indent=2, default=float))


def _table(results: dict[str, Any]) -> None:
    t = Table(title="contact classification, typical world (right: the final class at the offset)")
    t.add_column("scene", justify="left")
    for kind in CONTACT_KINDS:
        t.add_column(f"{kind} right (missed)", justify="right")
    t.add_column("intent right at onset", justify="right")
    t.add_column("m_eff within 10 % (n)", justify="right")
    t.add_column("m_eff median error", justify="right")
    for scene, r in results.items():
        k, m = r["kinds"], r["mass"]["all"]
        onset = _share([x["onset_intent_right"] for x in r["contacts"]])
        t.add_row(scene, *(f"{_pct(k[x]['right'])} of {k[x]['n']} ({k[x]['missed']})" for x in CONTACT_KINDS),
                  _pct(onset), f"{_pct(m['within_10'])} ({m['n']})",
                  "-" if math.isnan(m["median"]) else f"{100 * m['median']:.1f} %")
    table_console().print(t)


def _share(flags: list[bool]) -> float:
    return float(np.mean(flags)) if flags else math.nan


def _pct(x: float) -> str:
    return "-" if math.isnan(x) else f"{100 * x:.0f} %"
