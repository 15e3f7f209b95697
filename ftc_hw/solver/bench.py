"""``ftc bench solver``: accuracy against latency for each scene and method, with the Cramer-Rao bound.

Cases: contact points uniform (by area) on the touchable surfaces at the scene's home pose, forces
of 5-200 N uniform in direction within a friction cone of coefficient 1 (45 degrees about the inward
normal: a touch cannot transmit a more tangential force without slipping). Noise-free and with the
scene's sensor noise. Well-posed cases: those our solver answers without a flag on the noise-free
reading (not ambiguous, not grazing, ...). Error columns cover the well-posed cases that each method
answers without a flag; ``flagged_share`` and ``pos_err_mm_rms_all`` (flagged answers included)
show the rest. The Cramer-Rao bound is taken over the same cases as the errors.
"""
from __future__ import annotations

import json
import math
import platform
import time
from pathlib import Path

import numpy as np

from ..model import ArmModel, Contact
from ..scene import builtin_names, load_scene
from . import kernels as K
from . import make_solver

CHI2_2DOF_95 = 5.991464547107979
FRICTION_CONE_DEG = 45.0  # forces within a friction cone of coefficient 1: what a touch can transmit


def _contacts(model: ArmModel, q, n: int, rng: np.random.Generator):
    from sim_devices.world.scenarios import _cone, visible_filter

    from ..model.sampling import sample_surface_points

    pts = sample_surface_points(model, q, n, rng, hidden=visible_filter(model, q))
    return [(sp, _cone(-sp.normal, math.radians(FRICTION_CONE_DEG), rng) * rng.uniform(5.0, 200.0)) for sp in pts]


def crlb_point_cov(solver, point, normal, force) -> np.ndarray:
    """Cramer-Rao bound of the contact point (3x3, base frame, rank 2) for the 6-D wrench
    measurement with the point constrained to the surface: (J^T W J)^-1 at the truth."""
    t1, t2 = np.empty(3), np.empty(3)
    K._tangent_basis(np.asarray(normal, dtype=float), t1, t2)
    jac = np.empty((6, 5))
    K._jacobian(np.asarray(point, dtype=float), np.asarray(force, dtype=float), t1, t2, jac)
    info = jac.T @ solver._W0 @ jac
    cov = np.linalg.inv(info)
    tb = np.stack([t1, t2], axis=1)
    return tb @ cov[:2, :2] @ tb.T


def _coverage(err: np.ndarray, cov: np.ndarray) -> bool:
    """The true point inside the estimate's 95 % region (rank-2 covariance on the tangent plane)."""
    if not np.all(np.isfinite(cov)) or not np.any(cov):
        return False
    d2 = float(err @ np.linalg.pinv(cov, rcond=1e-12, hermitian=True) @ err)
    return d2 <= CHI2_2DOF_95


def _evaluate(solver, cases, readings, q, well_posed, crlb) -> dict:
    """Errors over the well-posed cases the method answers without a flag (a flag is the method
    saying it cannot be sure); ``pos_err_mm_rms_all`` and ``flagged_share`` show the rest."""
    pos, pos_all, dirs, mags, covered, bound = [], [], [], [], [], []
    flagged = 0
    lat = []
    for i, ((sp, force), w) in enumerate(zip(cases, readings, strict=True)):
        t0 = time.perf_counter_ns()
        e = solver.solve(w, q)
        lat.append((time.perf_counter_ns() - t0) / 1e3)
        if not well_posed[i]:
            continue
        err = e.point - sp.point
        pos_all.append(np.linalg.norm(err) * 1e3)
        if e.flags or not e.contact:
            flagged += 1
            continue
        pos.append(pos_all[-1])
        bound.append(crlb[i])
        fn, en = np.linalg.norm(force), np.linalg.norm(e.force)
        cosang = float(np.clip(e.force @ force / (fn * en), -1, 1)) if en > 0 else -1.0
        dirs.append(math.degrees(math.acos(cosang)))
        mags.append(abs(en - fn) / fn * 100)
        covered.append(_coverage(err, e.cov[:3, :3]))
    pos_a = np.array(pos)
    ws = np.array(readings)
    qs = np.repeat(q[None], len(ws), axis=0)
    solver.solve_batch(ws[:64], qs[:64])  # warm up (compilation, thread pool)
    t0 = time.perf_counter()
    solver.solve_batch(ws, qs)
    fps = len(ws) / (time.perf_counter() - t0)
    lat_a = np.array(lat[len(lat) // 10:])  # the first calls warm caches
    return {
        "pos_err_mm_median": float(np.median(pos_a)), "pos_err_mm_p95": float(np.percentile(pos_a, 95)),
        "pos_err_mm_max": float(pos_a.max()), "pos_err_mm_rms": float(np.sqrt(np.mean(pos_a**2))),
        "pos_err_mm_rms_all": float(np.sqrt(np.mean(np.square(pos_all)))),
        "crlb_pos_mm_rms": float(np.sqrt(np.mean(np.square(bound)))),
        "dir_err_deg_median": float(np.median(dirs)), "mag_err_pct_median": float(np.median(mags)),
        "coverage95": float(np.mean(covered)), "latency_us_median": float(np.median(lat_a)),
        "latency_us_p99": float(np.percentile(lat_a, 99)), "batch_frames_per_s": float(fps),
        "cases": int(len(pos_a)), "flagged_share": flagged / max(1, len(pos_all)),
    }


def run(json_path: Path | None = None, plot_path: Path | None = None, n: int = 2000, seed: int = 0,
        scenes: list[str] | None = None, methods: tuple[str, ...] = ("ours", "leng2016")) -> dict:
    from rich.console import Console
    from rich.table import Table

    console = Console()
    results: dict = {"noise_free": {}, "noisy": {}}
    for name in scenes or builtin_names():
        scene = load_scene(name)
        model = ArmModel(scene)
        q = np.array(scene.robot.home)
        rng = np.random.default_rng(seed)
        cases = _contacts(model, q, n, rng)
        clean = [model.predicted_wrench(q, level="bias", contacts=[Contact(sp.link, sp.point, f)]) for sp, f in cases]
        noise_std = np.sqrt(np.diag(scene.sensor.noise_cov))
        noisy = [w + rng.normal(size=6) * noise_std for w in clean]
        ours = make_solver(scene, "ours")
        well_posed = np.array([not ours.solve(w, q).flags for w in clean])
        crlb = [math.sqrt(np.trace(crlb_point_cov(ours, sp.point, ours.solve(w, q).normal, f))) * 1e3 if ok
                else math.nan for (sp, f), w, ok in zip(cases, clean, well_posed, strict=True)]
        for method in methods:
            solver = ours if method == "ours" else make_solver(scene, method)
            for label, readings in (("noise_free", clean), ("noisy", noisy)):
                r = _evaluate(solver, cases, readings, q, well_posed, crlb if label == "noisy" else [0.0] * n)
                r["well_posed_share"] = float(well_posed.mean())
                results[label].setdefault(name, {})[method] = r
    results["meta"] = {"cases_per_scene": n, "seed": seed, "python": platform.python_version(),
                       "machine": platform.machine(), "cpus": __import__("os").cpu_count()}
    for label in ("noise_free", "noisy"):
        table = Table(title=f"solver, {label.replace('_', '-')} ({n} contacts per scene, 5-200 N)")
        cols = ["scene", "method", "pos med mm", "p95 mm", "max mm", "rms mm", "CRLB rms mm", "dir deg", "mag %",
                "cover95", "lat med us", "lat p99 us", "batch fps"]
        for c in cols:
            table.add_column(c, justify="left" if c in ("scene", "method") else "right")
        for name, per in results[label].items():
            for method, r in per.items():
                table.add_row(name, method, f"{r['pos_err_mm_median']:.3g}", f"{r['pos_err_mm_p95']:.3g}",
                              f"{r['pos_err_mm_max']:.3g}", f"{r['pos_err_mm_rms']:.3g}", f"{r['crlb_pos_mm_rms']:.3g}",
                              f"{r['dir_err_deg_median']:.3g}", f"{r['mag_err_pct_median']:.3g}",
                              f"{r['coverage95']:.3f}", f"{r['latency_us_median']:.1f}", f"{r['latency_us_p99']:.1f}",
                              f"{r['batch_frames_per_s']:.0f}")
        console.print(table)
    if json_path is not None:
        json_path.write_text(json.dumps(results, indent=2))
    if plot_path is not None:
        _plot(results, plot_path)
    return results


def _plot(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for name, per in results["noisy"].items():
        for method, r in per.items():
            marker = "o" if method == "ours" else "s"
            ax.scatter(r["latency_us_median"], r["pos_err_mm_rms"], marker=marker, s=50, label=f"{name} / {method}")
            if method == "ours":
                ax.scatter(r["latency_us_median"], r["crlb_pos_mm_rms"], marker="_", s=200, color="k")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("latency per frame, median (us)")
    ax.set_ylabel("position error RMS (mm); bar: Cramer-Rao bound")
    ax.set_title("ftc bench solver: error against latency (scene sensor noise)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
