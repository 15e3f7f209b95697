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

Also: the share whose provisional class at onset already named the right intent.
"""
from __future__ import annotations

import json
import math
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rich.table import Table

from ftc_hw.bench.proprio import drive
from ftc_hw.bench.report import table_console
from ftc_hw.model import ArmModel
from ftc_hw.pipeline import PipelineSettings, pipeline_for
from ftc_hw.scene import Scene, load_scene
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


@dataclass(frozen=True)
class Job:
    scene: str
    draw: int
    count: int


def run_world(scene: Scene, world_scene: Scene, seed: int, count: int) -> tuple[tuple[PlannedContact, ...], list]:
    """The scripted contacts' plan and every contact event the scene's pipeline reported (with its world time)."""
    setup, plan = plan_contacts(scene, ArmModel(scene), np.random.default_rng(seed), CONTACT_KINDS, count)
    world = World(world_scene, setup, seed=seed)
    # every scripted contact moves the arm: a scene compensated for gravity only (its arm's inertial loads read
    # as contact) is run at the dynamics level
    pipe = pipeline_for(scene, PipelineSettings().with_level("dynamics"))
    events = [e for _, res, _ in drive(scene, world, pipe, run_length(plan)) for e in res.events]
    return plan, events


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
    try:
        plan, events = run_world(scene, world_scene, 100 + job.draw, job.count)
    except RuntimeError as exc:  # no scripted contact could be planned: said in the results, the others go on
        return {"scene": job.scene, "draw": job.draw, "contacts": [], "error": str(exc)}
    return {"scene": job.scene, "draw": job.draw, "contacts": judge(plan, events)}


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


def run(json_path: Path | None = None, *, scenes: tuple[str, ...] = SCENES, draws: int = 2, count: int = 10,
        workers: int | None = None) -> dict[str, Any]:
    """Every scene over ``draws`` typical draws, ``count`` contacts of each kind per draw, in worker processes;
    the table, and the results as JSON at ``json_path``."""
    jobs = [Job(s, d, count) for s in scenes for d in range(draws)]
    workers = workers or max(1, min(len(jobs), os.cpu_count() or 1))
    with ProcessPoolExecutor(workers) as pool:
        done = list(pool.map(run_job, jobs))
    results = {}
    for s in scenes:
        rows = [c for d in done if d["scene"] == s for c in d["contacts"]]
        errors = [d["error"] for d in done if d["scene"] == s and "error" in d]
        results[s] = {"kinds": summarize(rows), "contacts": rows} | ({"errors": errors} if errors else {})
    _table(results)
    if json_path is not None:
        json_path.write_text(json.dumps({"world": "typical", "draws": draws, "count": count, "scenes": results},
                                        indent=2, default=float))
    return results


def _table(results: dict[str, Any]) -> None:
    t = Table(title="contact classification, typical world (right: the final class at the offset)")
    t.add_column("scene", justify="left")
    for kind in CONTACT_KINDS:
        t.add_column(f"{kind} right (missed)", justify="right")
    t.add_column("intent right at onset", justify="right")
    for scene, r in results.items():
        k = r["kinds"]
        onset = _share([x["onset_intent_right"] for x in r["contacts"]])
        t.add_row(scene, *(f"{_pct(k[x]['right'])} of {k[x]['n']} ({k[x]['missed']})" for x in CONTACT_KINDS),
                  _pct(onset))
    table_console().print(t)


def _share(flags: list[bool]) -> float:
    return float(np.mean(flags)) if flags else math.nan


def _pct(x: float) -> str:
    return "-" if math.isnan(x) else f"{100 * x:.0f} %"
