"""``ftc bench solver``: accuracy against latency for each scene and method, with the Cramer-Rao bound.

Cases: contact points uniform (by area) on the touchable surfaces at the scene's home pose, forces
of 5-200 N uniform in direction within a friction cone of coefficient 1 (45 degrees about the inward
normal: a touch cannot transmit a more tangential force without slipping). Noise-free and with the
scene's sensor noise. Well-posed cases: those our solver answers without a flag on the noise-free
reading (not ambiguous, not grazing, ...).

Every method is scored on the same cases: the well-posed ones that all methods answer without a
flag (a flag is a method saying it cannot be sure). ``own_cases`` holds each method's columns over
its own unflagged cases; ``flagged_share`` and ``pos_err_mm_rms_all`` (flagged answers included)
show the rest. The Cramer-Rao bound is taken over the same cases as the errors. ``ours_minus_this``
gives each error column's difference to ours with a 95 % paired-bootstrap interval: medians of a few
thousand cases differ by chance by a few per cent, so "better" means an interval below zero
(its ``verdict``: better, worse, or tie when the interval holds 0).

Force magnitude has its own bound. The moment constrains the force only through tau . f = 0, whose
gradient in f is tau, perpendicular to f: it tells almost nothing about the force's scale. So the
magnitude can do at best what the bound gives (``crlb_mag_pct_median``: the median error an
estimator at the bound would show on these cases), and |f_measured| does what the force reading
alone gives (``force_only_mag_pct_median``). The two are equal when the force noise is isotropic:
then no unbiased estimator from this wrench beats |f_measured| on magnitude.
"""
from __future__ import annotations

import json
import math
import platform
import time
from pathlib import Path

import numpy as np
from rich.table import Table

from ftc_hw.bench.report import table_console
from ftc_hw.model import ArmModel, Contact
from ftc_hw.scene import builtin_names, load_scene
from ftc_hw.sim_devices.world.scenarios import sample_contacts
from ftc_hw.solver import make_solver
from ftc_hw.solver.bound import crlb_magnitude_std, crlb_point_cov

CHI2_2DOF_95 = 5.991464547107979
BATCH_RUNS = 5
FRICTION_CONE_DEG = 45.0  # forces within a friction cone of coefficient 1: what a touch can transmit


def _contacts(model: ArmModel, q, n: int, rng: np.random.Generator):

    return sample_contacts(model, q, n, rng, FRICTION_CONE_DEG, (5.0, 200.0))


def _scene_cases(name: str, n: int, seed: int):
    """(scene, model, q, cases, clean readings (n, 6), noisy readings (n, 6)): the bench's contacts
    at the scene's home pose and their sensor readings, noise-free and with the scene's noise."""
    scene = load_scene(name)
    model = ArmModel(scene)
    q = np.array(scene.robot.home)
    rng = np.random.default_rng(seed)
    cases = _contacts(model, q, n, rng)
    clean = np.array([model.predicted_wrench(q, level="bias", contacts=[Contact(sp.link, sp.point, f)])
                      for sp, f in cases])
    noisy = clean + rng.normal(size=clean.shape) * np.sqrt(np.diag(scene.sensor.noise_cov))
    return scene, model, q, cases, clean, noisy


def median_abs_normal(std: np.ndarray) -> float:
    """Median of |e| over cases with e ~ N(0, std_i^2), one case drawn uniformly: the median
    absolute error an estimator at these standard deviations would show."""
    std = np.asarray(std, dtype=float)
    if std.size == 0:
        return math.nan
    lo, hi = 0.0, 10.0 * float(std.max())
    for _ in range(100):  # bisection on the mixture's CDF of |e|
        mid = 0.5 * (lo + hi)
        cdf = np.mean([math.erf(mid / (s * math.sqrt(2.0))) if s > 0 else 1.0 for s in std])
        lo, hi = (mid, hi) if cdf < 0.5 else (lo, mid)
    return 0.5 * (lo + hi)


def _coverage(err: np.ndarray, cov: np.ndarray) -> bool:
    """The true point inside the estimate's 95 % region (rank-2 covariance on the tangent plane)."""
    if not np.all(np.isfinite(cov)) or not np.any(cov):
        return False
    d2 = float(err @ np.linalg.pinv(cov, rcond=1e-12, hermitian=True) @ err)
    return d2 <= CHI2_2DOF_95


def _solve_all(solver, readings, q) -> tuple[list, np.ndarray, float]:
    """Every case through the single-frame path (timed), then the batch path (throughput)."""
    estimates, lat = [], []
    for w in readings:
        t0 = time.perf_counter_ns()
        estimates.append(solver.solve(w, q))
        lat.append((time.perf_counter_ns() - t0) / 1e3)
    ws = np.array(readings)
    qs = np.repeat(q[None], len(ws), axis=0)
    solver.solve_batch(ws[:64], qs[:64])  # warm up (compilation, thread pool)
    runs = []
    for _ in range(BATCH_RUNS):  # one call is a few ms: the median of several steadies it
        t0 = time.perf_counter()
        solver.solve_batch(ws, qs)
        runs.append(time.perf_counter() - t0)
    fps = len(ws) / float(np.median(runs))
    return estimates, np.array(lat[len(lat) // 10:]), fps  # the first calls warm caches


def _answered(estimates) -> np.ndarray:
    """The cases a method answers without a flag (a flag is the method saying it cannot be sure)."""
    return np.array([bool(e.contact and not e.flags) for e in estimates])


def _errors(cases, estimates) -> dict[str, np.ndarray]:
    """Per-case errors: position (mm), force direction (deg), force magnitude (%), 95 % coverage."""
    pos, dirs, mags, covered = [], [], [], []
    for (sp, force), e in zip(cases, estimates, strict=True):
        err = e.point - sp.point
        pos.append(np.linalg.norm(err) * 1e3)
        fn, en = np.linalg.norm(force), np.linalg.norm(e.force)
        cosang = float(np.clip(e.force @ force / (fn * en), -1, 1)) if en > 0 else -1.0
        dirs.append(math.degrees(math.acos(cosang)))
        mags.append(abs(en - fn) / fn * 100)
        covered.append(_coverage(err, e.cov[:3, :3]))
    return {"pos": np.array(pos), "dir": np.array(dirs), "mag": np.array(mags), "cov": np.array(covered, dtype=float)}


_STATS = {  # column -> (per-case error, statistic)
    "pos_err_mm_median": ("pos", np.median), "pos_err_mm_p95": ("pos", lambda a: np.percentile(a, 95)),
    "pos_err_mm_max": ("pos", np.max), "pos_err_mm_rms": ("pos", lambda a: np.sqrt(np.mean(a**2))),
    "dir_err_deg_median": ("dir", np.median), "mag_err_pct_median": ("mag", np.median),
}


def _columns(err: dict[str, np.ndarray], sel: np.ndarray, bound: dict[str, np.ndarray]) -> dict:
    out = {col: float(stat(err[key][sel])) for col, (key, stat) in _STATS.items()}
    out["crlb_pos_mm_rms"] = float(np.sqrt(np.mean(np.square(bound["pos"][sel]))))
    out["crlb_mag_pct_median"] = median_abs_normal(bound["mag"][sel])
    out["force_only_mag_pct_median"] = median_abs_normal(bound["mag_force_only"][sel])
    out["coverage95"] = float(np.mean(err["cov"][sel]))
    out["cases"] = int(sel.sum())
    return out


def _bounds(solver, cases, clean_est, well_posed) -> dict[str, np.ndarray]:
    """Per case, at the truth: the point's Cramer-Rao RMS (mm), and the magnitude's standard
    deviation (% of |f|) at the bound and from the force reading alone. NaN where not well posed."""
    out = {k: np.full(len(cases), math.nan) for k in ("pos", "mag", "mag_force_only")}
    for i, ((sp, f), e, ok) in enumerate(zip(cases, clean_est, well_posed, strict=True)):
        if ok:
            out["pos"][i] = math.sqrt(np.trace(crlb_point_cov(solver, sp.point, e.normal, f))) * 1e3
            mag, force_only = crlb_magnitude_std(solver, sp.point, e.normal, f)
            fn = np.linalg.norm(f)
            out["mag"][i], out["mag_force_only"][i] = 100 * mag / fn, 100 * force_only / fn
    return out


def _paired(err_a: dict, err_b: dict, sel: np.ndarray, rng: np.random.Generator, n_boot: int = 400) -> dict:
    """Each error column's difference a - b on the same cases, with a 95 % paired-bootstrap interval:
    an interval that holds 0 means the sample cannot tell the two methods apart in that column."""
    idx = np.flatnonzero(sel)
    draws = rng.integers(0, len(idx), size=(n_boot, len(idx)))
    return {col: _paired_difference(err_a[key][idx], err_b[key][idx], stat, draws)
            for col, (key, stat) in _STATS.items()}


def _paired_difference(a: np.ndarray, b: np.ndarray, stat, draws: np.ndarray) -> dict:
    """stat(a) - stat(b) over paired cases, its 95 % interval over the bootstrap ``draws`` (rows of
    case indices) and the verdict: better (interval below 0), worse (above) or tie."""
    boot = [stat(a[d]) - stat(b[d]) for d in draws]
    lo, hi = np.percentile(boot, [2.5, 97.5])
    verdict = "better" if hi < 0 else "worse" if lo > 0 else "tie"
    return {"diff": float(stat(a) - stat(b)), "ci95": [float(lo), float(hi)], "verdict": verdict}


def run(json_path: Path | None = None, plot_path: Path | None = None, n: int = 2000, seed: int = 0,
        scenes: list[str] | None = None, methods: tuple[str, ...] = ("ours", "leng2016"),
        magnitude_cases: int = 0) -> dict:
    """``magnitude_cases`` > 0: also :func:`magnitude_check` on that many cases per scene, in the
    results as ``magnitude_vs_force_reading``."""

    console = table_console()
    results: dict = {"noise_free": {}, "noisy": {}}
    for name in scenes or builtin_names():
        scene, model, q, cases, clean, noisy = _scene_cases(name, n, seed)
        ours = make_solver(scene, "ours")
        clean_est = [ours.solve(w, q) for w in clean]
        well_posed = np.array([not e.flags for e in clean_est])
        bounds = _bounds(ours, cases, clean_est, well_posed)
        solvers = {m: ours if m == "ours" else make_solver(scene, m) for m in methods}
        for label, readings in (("noise_free", clean), ("noisy", noisy)):
            runs = {m: _solve_all(s, readings, q) for m, s in solvers.items()}
            errs = {m: _errors(cases, est) for m, (est, _, _) in runs.items()}
            answered = {m: _answered(est) for m, (est, _, _) in runs.items()}
            common = well_posed & np.logical_and.reduce(list(answered.values()))
            bound = bounds if label == "noisy" else {k: np.zeros(n) for k in bounds}
            per = results[label].setdefault(name, {})
            for m, (_est, lat, fps) in runs.items():
                own = well_posed & answered[m]
                r = _columns(errs[m], common, bound)  # every method on the same cases
                r.update(latency_us_median=float(np.median(lat)), latency_us_p99=float(np.percentile(lat, 99)),
                         batch_frames_per_s=float(fps), well_posed_share=float(well_posed.mean()),
                         flagged_share=float(1.0 - own.sum() / max(1, well_posed.sum())),
                         pos_err_mm_rms_all=float(np.sqrt(np.mean(np.square(errs[m]["pos"][well_posed])))),
                         own_cases=_columns(errs[m], own, bound))
                if m != "ours" and "ours" in errs:
                    r["ours_minus_this"] = _paired(errs["ours"], errs[m], common, np.random.default_rng(seed))
                per[m] = r
    results["meta"] = {"cases_per_scene": n, "seed": seed, "python": platform.python_version(),
                       "machine": platform.machine(), "cpus": __import__("os").cpu_count()}
    for label in ("noise_free", "noisy"):
        table = Table(title=f"solver, {label.replace('_', '-')} ({n} contacts per scene, 5-200 N)")
        cols = ["scene", "method", "pos med mm", "p95 mm", "max mm", "rms mm", "CRLB rms mm", "dir deg", "mag %",
                "CRLB mag %", "cover95", "lat med us", "lat p99 us", "batch fps"]
        for c in cols:
            table.add_column(c, justify="left" if c in ("scene", "method") else "right")
        for name, per in results[label].items():
            for method, r in per.items():
                table.add_row(name, method, f"{r['pos_err_mm_median']:.3g}", f"{r['pos_err_mm_p95']:.3g}",
                              f"{r['pos_err_mm_max']:.3g}", f"{r['pos_err_mm_rms']:.3g}", f"{r['crlb_pos_mm_rms']:.3g}",
                              f"{r['dir_err_deg_median']:.3g}", f"{r['mag_err_pct_median']:.3g}",
                              f"{r['crlb_mag_pct_median']:.3g}",
                              f"{r['coverage95']:.3f}", f"{r['latency_us_median']:.1f}", f"{r['latency_us_p99']:.1f}",
                              f"{r['batch_frames_per_s']:.0f}")
        console.print(table)
    _print_paired(console, results["noisy"], n)
    if magnitude_cases:
        results["magnitude_vs_force_reading"] = magnitude_check(magnitude_cases, seed, scenes)
        _print_magnitude_check(console, results["magnitude_vs_force_reading"])
    if json_path is not None:
        json_path.write_text(json.dumps(results, indent=2))
    if plot_path is not None:
        _plot(results, plot_path)
    return results


def magnitude_check(n: int, seed: int = 0, scenes: list[str] | None = None, n_boot: int = 400) -> dict:
    """Force magnitude, ours against |f_measured| (exactly the leng2016 method's magnitude, so no
    leng2016 solve is needed), on many noisy cases through the batch path: the difference is a few
    thousandths of a per cent, which a 2000-case run cannot resolve. Per scene: the cases both
    answer (ours unflagged on the clean and the noisy reading), the two medians (% of |f|) and
    their difference with a 95 % paired-bootstrap interval and its verdict."""
    out = {}
    for name in scenes or builtin_names():
        scene, _, q, cases, clean, noisy = _scene_cases(name, n, seed)
        solver = make_solver(scene, "ours")
        qs = np.repeat(q[None], n, axis=0)
        est_clean, est = solver.solve_batch(clean, qs), solver.solve_batch(noisy, qs)
        ok = est_clean.contact & (est_clean.flags == 0) & est.contact & (est.flags == 0)
        true = np.linalg.norm([f for _, f in cases], axis=1)
        ours = (np.abs(np.linalg.norm(est.force, axis=1) - true) / true * 100)[ok]
        reading = (np.abs(np.linalg.norm(noisy[:, :3], axis=1) - true) / true * 100)[ok]
        draws = np.random.default_rng(seed).integers(0, ours.size, size=(n_boot, ours.size))
        out[name] = {"cases": int(ok.sum()), "ours_pct_median": float(np.median(ours)),
                     "force_reading_pct_median": float(np.median(reading)),
                     **_paired_difference(ours, reading, np.median, draws)}
    return out


def _print_magnitude_check(console, check: dict) -> None:

    table = Table(title="force magnitude error, median % of |f|: ours against |f_measured| (the leng2016 "
                        "method's magnitude), same noisy cases, 95 % paired bootstrap")
    for c in ("scene", "cases", "ours", "|f_measured|", "ours minus", "95 % interval", "verdict"):
        table.add_column(c, justify="left" if c in ("scene", "verdict") else "right")
    for name, r in check.items():
        table.add_row(name, str(r["cases"]), f"{r['ours_pct_median']:.6f}", f"{r['force_reading_pct_median']:.6f}",
                      f"{r['diff']:+.2e}", f"[{r['ci95'][0]:+.2e}, {r['ci95'][1]:+.2e}]", r["verdict"])
    console.print(table)


def _print_paired(console, noisy: dict, n: int) -> None:

    if not any("ours_minus_this" in r for per in noisy.values() for r in per.values()):
        return
    table = Table(title="ours minus the other method, with the scene's noise, same cases (95 % paired bootstrap)")
    table.add_column("scene")
    table.add_column("vs")
    for col in _STATS:
        table.add_column(col.replace("_", " "), justify="right")
    for name, per in noisy.items():
        for method, r in per.items():
            if "ours_minus_this" not in r:
                continue
            cells = [f"{d['diff']:+.3g} [{d['ci95'][0]:+.2g}, {d['ci95'][1]:+.2g}] {d['verdict']}"
                     for d in r["ours_minus_this"].values()]
            table.add_row(name, method, *cells)
    console.print(table)


def _plot(results: dict, path: Path) -> None:
    import matplotlib  # lazy: matplotlib only for --plot

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: matplotlib only for --plot

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
