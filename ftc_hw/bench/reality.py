"""``ftc bench reality``: what each difference between a real arm and its model costs, and what
identification wins back.

For each scene and each of several seeded draws of the world, the pipeline (dynamics level, tared at
rest) runs over recordings of the drawn world (``ftc_hw.bench.compensation.record``: the F/T
readings and joint state the devices would deliver, with the world's truth):

- free motion: the ``sweep`` (false alarms, the residual force, moment and detection statistic);
- contacts: ``sweep-with-collision`` (moving) and ``static-pokes`` (random surface points, 5 N up
  to the scene's poke limit): detection and delay over the contacts above 10 N, and the events'
  points against the truth: error and 95 % coverage of the point's reported uncertainty over the
  unflagged events (an ``ambiguous`` or ``uncertain`` one says itself that its point may be off),
  the right link over all, and the share flagged.

Columns: ``ideal`` (the world is the model), ``typical`` without identification, ``typical+id`` and
``harsh+id`` (identified from a planned excitation in the same drawn world first, ``ftc identify
--plan``'s fit), ``typical+id-sweep`` (identified from the ordinary sweep instead), and, one
difference at a time, what each costs without identification (``only:<difference>``).
"""
from __future__ import annotations

import dataclasses
import fnmatch
import json
import math
import os
import platform
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rich.table import Table

from ftc_hw.app.calibration.identify import identify
from ftc_hw.bench.compensation import Recording, record
from ftc_hw.bench.report import table_console
from ftc_hw.calibration.free_motion import MotionData
from ftc_hw.model.mesh_surface import MeshShell, pipeline_mesh_shell
from ftc_hw.pipeline import ContactPipeline, Corrections, LocalizationSettings, MotionSettings, PipelineSettings
from ftc_hw.scene import Scene, builtin_names, load_scene
from ftc_hw.sim_devices.world import DIFFERENCES, with_reality
from ftc_hw.tracking import FUSED_FLAGS

TARE_FROM_S, TARE_S = 0.05, 0.1  # at rest before anything moves or touches (static-pokes' first at 0.2 s)
CHI2_3_95 = 7.815  # 95 % quantile of chi-square, 3 dof
DETECTABLE_N = 10.0  # contacts above this must be detected


@dataclass(frozen=True)
class Column:
    name: str
    reality: str
    identify_from: str | None = None  # None, "excitation" or "sweep"
    only: str | None = None  # one difference drawn on its own


MAIN_COLUMNS = (Column("ideal", "ideal"), Column("typical", "typical"),
                Column("typical+id", "typical", "excitation"), Column("harsh+id", "harsh", "excitation"),
                Column("typical+id-sweep", "typical", "sweep"))
COST_COLUMNS = tuple(Column(f"only:{d}", "typical", only=d) for d in DIFFERENCES)
ALL_COLUMNS = MAIN_COLUMNS + COST_COLUMNS


def select_columns(columns: tuple[Column, ...], patterns: list[str] | None) -> tuple[Column, ...]:
    """The columns whose names match one of ``patterns`` (shell globs, e.g. ``only:*``), in table order."""
    if not patterns:
        return columns
    unknown = [p for p in patterns if not any(fnmatch.fnmatchcase(c.name, p) for c in columns)]
    if unknown:
        raise ValueError(f"no column matches {', '.join(unknown)}: the columns are "
                         f"{', '.join(c.name for c in columns)}")
    return tuple(c for c in columns if any(fnmatch.fnmatchcase(c.name, p) for p in patterns))


@dataclass(frozen=True)
class Job:
    scene: str
    column: Column
    draw: int
    free_s: float
    contact_s: float
    identify_s: float


def run_job(job: Job) -> dict[str, Any]:
    """One scene, column and draw: identify if asked, then the free and contact runs."""
    scene = load_scene(job.scene)
    only = (job.column.only,) if job.column.only else None
    world = with_reality(scene, job.column.reality, seed=job.draw, only=only)
    corrections = Corrections()
    if job.column.identify_from:
        train = record(scene, job.column.identify_from, job.identify_s, 1.0, 1000 + job.draw, world)
        cal, _ = identify(scene, [MotionData(train.t, train.wrench, train.q, train.qd, train.current)], None,
                          f"bench: {job.column.identify_from}")
        corrections = dataclasses.replace(cal.corrections(scene), bias=None)  # tared at rest like every column
    shell = pipeline_mesh_shell(scene)
    settings = PipelineSettings(corrections=corrections, motion=MotionSettings(level="dynamics"),
                                localization=LocalizationSettings(surface="primitives"))
    free = _run(scene, record(scene, "sweep", job.free_s, 1.0, job.draw, world), settings)
    moving = _run(scene, record(scene, "sweep-with-collision", job.contact_s, 1.0, job.draw, world), settings, shell)
    pokes = _run(scene, record(scene, "static-pokes", job.contact_s, 1.0, job.draw, world), settings, shell)
    return _summarize(free, [moving, pokes])


def _run(scene: Scene, rec: Recording, settings: PipelineSettings, shell: MeshShell | None = None) -> dict[str, Any]:
    """The pipeline over one recording. Its events are taken on the primitives and moved onto ``shell``
    by the pipeline's own step (what it does with ``surface="meshes"``), so both are measured."""
    pipe = ContactPipeline(scene, settings)
    i0, i1 = np.searchsorted(rec.t, [TARE_FROM_S, TARE_FROM_S + TARE_S])
    pipe.tare(rec.wrench[i0:i1].mean(axis=0), rec.q[i0:i1].mean(axis=0), i1 - i0, int(rec.t[i1] * 1e9))
    resid, stat, onsets, offsets, points = [], [], [], [], []
    for i in range(i1, len(rec.t)):
        r = pipe.process(int(round(rec.t[i] * 1e9)), rec.wrench[i], rec.q[i], rec.qd[i], rec.current[i],
                         saturated=bool(rec.saturated[i]))
        if not rec.contact[i] and not _near_contact(rec, i):
            resid.append(r.external)
            stat.append(r.detection.d2)
        for e in r.events:
            if e.kind == "onset":
                onsets.append(rec.t[i])
            elif e.kind == "offset":
                offsets.append(rec.t[i])
            if e.kind in ("onset", "update") and rec.contact[i] and "no_estimate" not in e.flags:
                shipped = pipe.on_meshes(e, rec.q[i], shell, pipe.recent_external()) if shell is not None else e
                err = np.asarray(shipped.point) - rec.point[i]
                std = np.maximum(np.asarray(shipped.point_std), 1e-9)
                prim_err = (None if shell is None else
                            float(np.linalg.norm(np.asarray(e.point) - rec.point[i])) * 1e3)
                points.append((float(np.linalg.norm(err)) * 1e3, float(np.sum((err / std) ** 2)) <= CHI2_3_95,
                               e.link == rec.link[i], FUSED_FLAGS.issuperset(e.flags), prim_err,
                               shipped is e and shell is not None and e.link in shell.meshes,
                               float(rec.force[i])))
    return {"t": rec.t, "contact": rec.contact, "force": rec.force, "resid": np.array(resid).reshape(-1, 6),
            "stat": np.array(stat), "onsets": onsets, "offsets": offsets, "points": points,
            "threshold": pipe.detector.on}


def _near_contact(rec: Recording, i: int, margin_s: float = 0.3) -> bool:
    k = int(margin_s / max(rec.t[1] - rec.t[0], 1e-9))
    return bool(rec.contact[max(0, i - k):i + k].any())


def _episodes(rec: dict[str, Any], merge_s: float = 0.02) -> list[tuple[float, float, float]]:
    """(start, end, peak force) of each true contact."""
    out: list[list[float]] = []
    for ti, c, f in zip(rec["t"], rec["contact"], rec["force"], strict=True):
        if not c:
            continue
        if out and ti - out[-1][1] <= merge_s:
            out[-1][1] = ti
            out[-1][2] = max(out[-1][2], f)
        else:
            out.append([ti, ti, f])
    return [(a, b, c) for a, b, c in out]


def _summarize(free: dict[str, Any], contact_runs: list[dict[str, Any]]) -> dict[str, Any]:
    minutes = 0.0
    false_alarms = 0
    delays, contacts, detected, merged, points = [], 0, 0, 0, []
    for run in [free, *contact_runs]:
        eps = _episodes(run)
        free_s = (1.0 - run["contact"].mean()) * (run["t"][-1] - run["t"][0])
        minutes += free_s / 60.0
        for t_on in run["onsets"]:
            if not any(a - 0.001 <= t_on <= b + 0.02 for a, b, _ in eps):
                false_alarms += 1
        for k, (a, b, peak) in enumerate(eps):
            first = next((t for t in run["onsets"] if a - 0.001 <= t <= b), None)
            held = first is None and _held_from_earlier(run, eps[:k], a)
            if peak >= DETECTABLE_N:
                contacts += 1
                detected += first is not None or held
                merged += held
            if first is not None:
                delays.append((first - a) * 1e3)
        points += run["points"]
    resid = free["resid"]
    trusted = [p for p in points if p[3]]  # unflagged (an ambiguous or uncertain event says so itself)
    err, prim, misses = _errors(trusted)
    strong = np.array([p[0] for p in trusted if p[6] >= DETECTABLE_N], dtype=float)
    empty = (np.array([]), np.array([]), 0)
    by_run = [_errors([p for p in run["points"] if p[3]]) for run in contact_runs]
    by_run += [empty] * (len(CONTACT_RUNS) - len(by_run))  # a summary of fewer runs (tests)
    return {
        "residual_rms_N": float(np.sqrt(np.mean(np.sum(resid[:, :3] ** 2, axis=1)))) if len(resid) else math.nan,
        "residual_rms_Nm": float(np.sqrt(np.mean(np.sum(resid[:, 3:] ** 2, axis=1)))) if len(resid) else math.nan,
        "statistic_p99_over_threshold": (float(np.percentile(free["stat"], 99)) / free["threshold"]
                                         if len(free["stat"]) else math.nan),
        "false_alarms": false_alarms, "free_minutes": minutes,
        "false_alarms_per_min": false_alarms / minutes if minutes > 0 else math.nan,
        "contacts_over_10N": contacts, "detected_over_10N": detected, "merged_over_10N": merged,
        "delay_ms_median": _pct(delays, 50), "delay_ms_p95": _pct(delays, 95),
        "pos_err_mm_median": _pct(err, 50), "pos_err_mm_p95": _pct(err, 95),
        # the events while the true force was above 10 N (the contacts that must be detected): a weak
        # touch's line of action is as uncertain as its wrench is small beside the sensor's noise
        "pos_err_mm_median_over10N": _pct(strong, 50), "pos_err_mm_p95_over10N": _pct(strong, 95),
        # where the scene has meshes, the pipeline answers on them (above); on the primitives it fits, the
        # other way to localize on a real shell, measured side by side
        "pos_err_mm_median_primitives": _pct(prim, 50), "pos_err_mm_p95_primitives": _pct(prim, 95),
        "mesh_misses": misses,  # events on a meshed link whose line missed its meshes (kept on the primitives)
        # by scenario: the sweep's obstacle (hitting the true shell) and the scripted pokes (pressing it)
        **{f"pos_err_mm_{q}_{name}{kind}": _pct(values, pct)
           for name, (e, p, _) in zip(CONTACT_RUNS, by_run, strict=True)
           for kind, values in (("", e), ("_primitives", p)) for q, pct in (("median", 50), ("p95", 95))},
        "coverage95": float(np.mean([p[1] for p in trusted])) if trusted else math.nan,
        "link_right": float(np.mean([p[2] for p in points])) if points else math.nan,
        "flagged_share": 1.0 - len(trusted) / len(points) if points else math.nan,
        "estimates": len(points),
    }


CONTACT_RUNS = ("sweep", "pokes")  # the contact scenarios' short names, in run_job's order


def _errors(trusted: list[tuple]) -> tuple[np.ndarray, np.ndarray, int]:
    """Position errors (mm) as the pipeline answers, on the primitives (empty: the scene has no meshes),
    and how many events' lines missed their link's meshes."""
    err = np.array([p[0] for p in trusted], dtype=float)
    prim = np.array([p[4] for p in trusted if p[4] is not None], dtype=float)
    return err, prim, sum(bool(p[5]) for p in trusted)


def _held_from_earlier(run: dict[str, Any], earlier: list[tuple[float, float, float]], a: float) -> bool:
    """A contact that began while the monitor still reported an earlier true contact (its event open: the
    arm still rang from that touch when this one came), so it is reported within that event: detected,
    counted as merged. An event opened by a false alarm, or none open, does not count."""
    onset = max((t for t in run["onsets"] if t < a - 0.001), default=None)
    if onset is None or any(onset <= t < a for t in run.get("offsets", ())):
        return False
    return any(e0 - 0.001 <= onset <= e1 for e0, e1, _ in earlier)


def _pct(values, q: float) -> float:
    v = np.asarray(values, dtype=float)
    return float(np.percentile(v, q)) if len(v) else math.nan


FIGURES = ("residual_rms_N", "residual_rms_Nm", "statistic_p99_over_threshold", "false_alarms_per_min",
           "delay_ms_median", "delay_ms_p95", "pos_err_mm_median", "pos_err_mm_p95", "coverage95", "link_right",
           "flagged_share", "pos_err_mm_median_primitives", "pos_err_mm_p95_primitives",
           "pos_err_mm_median_over10N", "pos_err_mm_p95_over10N",
           *(f"pos_err_mm_{q}_{name}{kind}" for name in CONTACT_RUNS for kind in ("", "_primitives")
             for q in ("median", "p95")))
COUNTS = ("false_alarms", "free_minutes", "contacts_over_10N", "detected_over_10N", "merged_over_10N", "mesh_misses",
          "estimates")
WORSE_HIGH = {"coverage95": False, "link_right": False}  # for these, the worst draw is the lowest


def _combine(draws: list[dict[str, Any]]) -> dict[str, Any]:
    """Median over the draws of each figure, the worst draw's, and the totals."""
    out: dict[str, Any] = {}
    for k in FIGURES:
        v = np.array([d[k] for d in draws], dtype=float)
        v = v[np.isfinite(v)]
        out[k] = float(np.median(v)) if len(v) else math.nan
        worst = (v.min() if not WORSE_HIGH.get(k, True) else v.max()) if len(v) else math.nan
        out[f"{k}_worst"] = float(worst)
    fa, minutes = sum(d["false_alarms"] for d in draws), sum(d["free_minutes"] for d in draws)
    out["false_alarms_per_min"] = fa / minutes if minutes else math.nan  # pooled over every draw
    out.update(false_alarms=fa, free_minutes=minutes, draws=len(draws),
               contacts_over_10N=sum(d["contacts_over_10N"] for d in draws),
               detected_over_10N=sum(d["detected_over_10N"] for d in draws),
               merged_over_10N=sum(d["merged_over_10N"] for d in draws),
               mesh_misses=sum(d["mesh_misses"] for d in draws), estimates=sum(d["estimates"] for d in draws))
    return out


def run(json_path: Path | None = None, plot_path: Path | None = None, scenes: list[str] | None = None,
        draws: int = 5, free_minutes: float = 2.0, contact_minutes: float = 1.0, identify_minutes: float = 2.0,
        costs: bool = True, workers: int | None = None, only_columns: list[str] | None = None) -> dict[str, Any]:
    columns = select_columns(MAIN_COLUMNS + (COST_COLUMNS if costs else ()), only_columns)
    names = scenes or builtin_names()
    jobs = [Job(s, c, d, free_minutes * 60, contact_minutes * 60, identify_minutes * 60)
            for s in names for c in columns for d in range(draws if c.reality != "ideal" else 1)]
    outs: list[dict[str, Any] | None] = [None] * len(jobs)
    with ProcessPoolExecutor(max_workers=workers or os.cpu_count() or 1) as pool:
        futures = {pool.submit(run_job, j): k for k, j in enumerate(jobs)}
        for done, fut in enumerate(as_completed(futures), 1):
            k = futures[fut]
            outs[k] = fut.result()
            j = jobs[k]
            table_console().print(f"[{done}/{len(jobs)}] {j.scene} {j.column.name} draw {j.draw}: "
                                  + json.dumps({n: outs[k][n] for n in FIGURES + COUNTS if n in outs[k]}))
    results: dict[str, Any] = {}
    for s in names:
        results[s] = {c.name: _combine([o for j, o in zip(jobs, outs, strict=True)
                                        if j.scene == s and j.column == c]) for c in columns}
    results["meta"] = {"draws": draws, "free_minutes_per_draw": free_minutes, "contact_minutes_per_draw":
                       contact_minutes, "identify_minutes": identify_minutes, "python": platform.python_version(),
                       "cpus": os.cpu_count(), "columns": [c.name for c in columns]}
    _table(results, names, columns)
    if json_path is not None:
        json_path.write_text(json.dumps(results, indent=2))
    if plot_path is not None:
        _plot(results, names, plot_path)
    return results


def _table(results: dict[str, Any], names: list[str], columns: tuple[Column, ...]) -> None:
    meta = results["meta"]
    table = Table(title=f"reality: {meta['draws']} draws per column, {meta['free_minutes_per_draw']:g} min of free "
                        f"sweep + {meta['contact_minutes_per_draw']:g} min of each contact scenario per draw "
                        "(median over draws / worst draw)")
    for c in ("scene", "column", "resid N", "resid N m", "stat p99/thr", "false alarms/min", "detected >10 N",
              "delay ms med/p95", "pos err mm med/p95", "on primitives mm", "sweep | pokes mm", "coverage 95 %",
              "link right", "flagged"):
        table.add_column(c, justify="left" if c in ("scene", "column") else "right")
    for s in names:
        for c in columns:
            r = results[s][c.name]
            table.add_row(s, c.name, f"{r['residual_rms_N']:.3g}", f"{r['residual_rms_Nm']:.3g} / "
                          f"{r['residual_rms_Nm_worst']:.3g}", f"{r['statistic_p99_over_threshold']:.2g}",
                          f"{r['false_alarms_per_min']:.3g} ({r['false_alarms']} in {r['free_minutes']:.0f} min)",
                          f"{r['detected_over_10N']}/{r['contacts_over_10N']}"
                          + (f" ({r['merged_over_10N']} merged)" if r.get("merged_over_10N") else ""),
                          f"{r['delay_ms_median']:.3g} / {r['delay_ms_p95']:.3g}",
                          f"{r['pos_err_mm_median']:.3g} / {r['pos_err_mm_p95']:.3g} (>10 N: "
                          f"{r['pos_err_mm_median_over10N']:.3g} / {r['pos_err_mm_p95_over10N']:.3g})",
                          _on_primitives(r), _by_scenario(r),
                          f"{r['coverage95']:.2f} / {r['coverage95_worst']:.2f}",
                          f"{r['link_right']:.2f} / {r['link_right_worst']:.2f}", f"{r['flagged_share']:.2f}")
    table_console().print(table)


def _on_primitives(r: dict[str, Any]) -> str:
    """Where the pipeline answered on meshes: the same events on the primitives (and the mesh misses)."""
    if math.isnan(r["pos_err_mm_median_primitives"]):
        return "-"
    return (f"{r['pos_err_mm_median_primitives']:.3g} / {r['pos_err_mm_p95_primitives']:.3g} "
            f"({r['mesh_misses']} miss)")


def _by_scenario(r: dict[str, Any]) -> str:
    return " | ".join(f"{r[f'pos_err_mm_median_{n}']:.3g} / {r[f'pos_err_mm_p95_{n}']:.3g}" for n in CONTACT_RUNS)


def _plot(results: dict[str, Any], names: list[str], path: Path) -> None:
    import matplotlib  # lazy: matplotlib only for --plot

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: matplotlib only for --plot

    cols = results["meta"]["columns"]
    fig, axes = plt.subplots(1, 3, figsize=(13, 4))
    for ax, key, label in zip(axes, ("false_alarms_per_min", "pos_err_mm_median", "coverage95"),
                              ("false alarms / min", "position error, median (mm)", "95 % coverage"), strict=True):
        for k, s in enumerate(names):
            ax.bar(np.arange(len(cols)) + 0.8 * k / len(names), [results[s][c][key] for c in cols],
                   width=0.8 / len(names), label=s)
        ax.set_xticks(np.arange(len(cols)) + 0.4 - 0.4 / len(names), cols, rotation=30, fontsize=7)
        ax.set_title(label)
    axes[0].legend(fontsize=7)
    fig.suptitle("ftc bench reality")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
