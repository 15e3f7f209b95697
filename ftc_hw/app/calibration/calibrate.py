"""``ftc calibrate``: the bench wizard. Connect to the scene's devices, plan the poses and show the
accuracy they should give, move the arm (or have it jogged) to each, wait for stillness, sample, fit,
show the results with their uncertainty and the verdict, save the calibration file.

Exit codes: 0 the verdict is ``good``; 3 ``poorly_excited`` or ``inconsistent`` (the file is still
written, with the verdict in it); 1 aborted or a device failed; 2 bad arguments.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.live import Live
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.prompt import Confirm
from rich.table import Table

from ftc_hw.calibration import (
    CalibrationError,
    FitOptions,
    GeometryModel,
    Identifier,
    StillnessGate,
    calibration_from_fit,
    plan_poses,
    save_calibration,
    take_sample,
)
from ftc_hw.calibration.acquire import pose_error
from ftc_hw.calibration.plan import visiting_order
from ftc_hw.devices.base import DeviceError
from ftc_hw.model import ArmModel, Payload
from ftc_hw.scene import Scene, SceneError

from .calibrate_plot import draw_calibration
from .device_session import DeviceSession, SessionError
from .fit_figure import plot_beside

JOG_TOLERANCE = 0.01  # rad: how close a jogged UR must be to the planned pose


def _fmt(v: float, scale: float, digits: int) -> str:
    return f"{v * scale:.{digits}f}" if np.isfinite(v) else "not identified"


# (row label with unit, key in the derived dicts, index, display scale, digits)
ROWS = [("mass g", "mass", None, 1e3, 2), ("com_x mm", "com", 0, 1e3, 3), ("com_y mm", "com", 1, 1e3, 3),
        ("com_z mm", "com", 2, 1e3, 3), ("force_bias_x N", "force_bias", 0, 1.0, 4),
        ("force_bias_y N", "force_bias", 1, 1.0, 4), ("force_bias_z N", "force_bias", 2, 1.0, 4),
        ("torque_bias_x N m", "torque_bias", 0, 1.0, 5), ("torque_bias_y N m", "torque_bias", 1, 1.0, 5),
        ("torque_bias_z N m", "torque_bias", 2, 1.0, 5)]


def _pick(d: dict, key: str, i: int | None) -> float:
    v = d.get(key)
    if v is None:
        return float("nan")
    return float(v if i is None else v[i])


def plan_table(plan) -> Table:
    t = Table(title=f"plan: {len(plan.q)} poses (D-optimal, inside the joint limits, no self-collision)")
    t.add_column("pose", justify="right")
    for j in range(plan.q.shape[1]):
        t.add_column(f"q{j + 1} deg", justify="right")
    for k, q in enumerate(plan.q, 1):
        t.add_row(str(k), *(f"{np.degrees(x):7.1f}" for x in q))
    return t


def expected_table(plan, sample_s: float) -> Table:
    t = Table(title=f"expected accuracy (1 sigma) before moving: {sample_s:g} s per pose, "
                    f"com for a {plan.expected_mass:g} kg payload")
    t.add_column("parameter")
    t.add_column("expected std", justify="right")
    for name, key, i, scale, digits in ROWS:
        t.add_row(name, _fmt(_pick(plan.expected_std, key, i), scale, digits))
    for name in plan.names[10:]:
        t.add_row(name, f"{plan.expected_std[name]:.3g}")
    return t


def results_table(fit, truth: dict | None) -> Table:
    t = Table(title=f"results: verdict {fit.verdict}")
    cols = ["parameter", "estimate", "std"] + (["truth", "error", "|err|/std"] if truth else [])
    for c in cols:
        t.add_column(c, justify="left" if c == "parameter" else "right")
    d, s = fit.derived, fit.derived_std
    for name, key, i, scale, digits in ROWS:
        est, sd = _pick(d, key, i), _pick(s, key, i)
        row = [name, _fmt(est, scale, digits), _fmt(sd, scale, digits)]
        if truth:
            tv = _pick(truth, key, i)
            err = est - tv
            row += [_fmt(tv, scale, digits), _fmt(err, scale, digits),
                    f"{abs(err) / sd:.2f}" if sd > 0 and np.isfinite(sd) else "-"]
        t.add_row(*row)
    for name in fit.names[10:]:
        t.add_row(name, f"{d[name]:.4g}", f"{s[name]:.2g}", *([""] * (3 if truth else 0)))
    return t


def json_record(fit, truth: dict | None) -> dict:
    d, s = fit.derived, fit.derived_std

    def clean(v):
        if isinstance(v, list):
            return [clean(x) for x in v]
        if isinstance(v, float) and not np.isfinite(v):
            return None
        return v

    std = {"mass_kg": clean(s["mass"]), "com_m": clean(s["com"]), "force_bias_N": clean(s["force_bias"]),
           "torque_bias_Nm": clean(s["torque_bias"])}
    std.update({k: clean(s[k]) for k in fit.names[10:]})
    out = {"mass_kg": d["mass"], "com_m": clean(d["com"]), "force_bias_N": d["force_bias"],
           "torque_bias_Nm": d["torque_bias"], "std": std, "verdict": fit.verdict, "reasons": list(fit.reasons),
           "poorly_excited": list(fit.poorly_excited), "residual_rms": fit.residual_rms.tolist(),
           "condition_number": clean(float(fit.condition_number))}
    out.update({k: d[k] for k in fit.names[10:]})
    if truth:
        out["truth"] = {"mass_kg": truth["mass"], "com_m": truth["com"], "force_bias_N": truth["force_bias"],
                        "torque_bias_Nm": truth["torque_bias"]}
    return out


def _ask(console: Console, interactive: bool, question: str, default: bool = True) -> bool:
    if not interactive:
        return True
    return Confirm.ask(question, console=console, default=default)


@dataclass(frozen=True)
class CalibrateOptions:
    """``ftc calibrate``'s: the devices (emulated with ``sim``), the plan, the fit, what is written."""

    sim: bool = False  # emulated devices, hiding ``sim_payload`` (default 0.5 kg 5 cm out along the flange's z)
    sim_payload: Payload | None = None
    reality: str = "ideal"  # with sim: how the world's arm differs from the model
    interactive: bool = True  # asks before moving and saving
    poses: int = 12  # planned poses
    sample_s: float = 1.0  # seconds of F/T samples per pose
    seed: int = 0  # planning candidates, simulated noise
    expected_mass: float = 0.5  # kg: the payload the plan's expected accuracy assumes
    speed: float = 1.0  # rad/s: peak joint speed of the moves
    fit: FitOptions = field(default_factory=FitOptions)  # what else is estimated: yaw, tilt, arm_gravity
    out: Path | None = None  # the calibration file (default calibration-<scene>.toml)
    json_path: Path | None = None
    plot: bool = True  # the fit drawn to a PNG beside the saved file


def run_calibrate(scene: Scene, options: CalibrateOptions) -> int:
    """The wizard on ``scene``'s devices. Returns the exit code (module docstring)."""
    console = Console()
    sim, interactive, reality, sample_s = options.sim, options.interactive, options.reality, options.sample_s
    payload = options.sim_payload
    if sim and payload is None:
        payload = Payload(0.5, (0.0, 0.0, 0.05))
    out = options.out or Path(f"calibration-{scene.name}.toml")
    console.print(f"[bold]ftc calibrate[/]: scene [cyan]{scene.name}[/]"
                  + (f" on [yellow]emulated devices[/] (hidden payload; reality {reality})" if sim else ""))
    session = DeviceSession(scene, sim=sim, sim_payload=payload, seed=options.seed, reality=reality)
    # planned before the devices start: then the planning has the CPU to itself (27 s instead of 5 s on
    # 2 cores beside the world and the emulators); the visiting order follows the arm's pose once known
    fit_options = replace(options.fit, q_std=session.q_resolution / np.sqrt(12))
    identifier = Identifier(GeometryModel(ArmModel(scene)), fit_options)
    n_samples = int(round(sample_s * scene.sensor.rate_hz))
    with console.status(f"planning {options.poses} poses"):
        plan = plan_poses(scene, identifier, options.poses, samples_per_pose=n_samples,
                          expected_mass=options.expected_mass, seed=options.seed)
    try:
        with console.status("connecting to the scene's devices"):
            session.start()
    except (SessionError, DeviceError, RuntimeError, OSError, SceneError) as exc:
        console.print(f"[red]cannot connect:[/] {exc}")
        return 1
    try:
        ft, arm = session.ft, session.arm
        console.print(f"F/T: {ft.describe()}  serial {session.sensor_serial or '(none reported)'}")
        console.print(f"arm: {arm.describe()}")
        if not session.can_command and not interactive:
            console.print("[red]this arm cannot be moved by the wizard (UR: jog it by hand): run without "
                          "--non-interactive[/]")
            return 1
        q_now, _ = session.joint_state()
        plan = replace(plan, q=visiting_order(plan.q, q_now))
        console.print(plan_table(plan))
        console.print(expected_table(plan, sample_s))
        if session.arm.moves_on_goals:
            question = (f"Torque on and move the arm through {len(plan.q)} poses? Keep hands and objects clear "
                        "of it")
        elif sim:
            console.print("[yellow]simulation: the emulated UR cannot be jogged over RTDE; the wizard sets the "
                          "world's joint targets directly[/]")
            question = f"Move the emulated arm through {len(plan.q)} poses?"
        else:
            question = f"Jog the arm to each of the {len(plan.q)} poses when asked?"
        if not _ask(console, interactive, question):
            console.print("aborted: nothing moved")
            return 1
        session.torque_on()
        gate = StillnessGate(scene)
        samples, sim_times, used = [], [], []
        for k, q_goal in enumerate(plan.q, 1):
            console.rule(f"pose {k}/{len(plan.q)}")
            if session.can_command:
                with Progress(TextColumn("{task.description}"), BarColumn(), TimeElapsedColumn(),
                              console=console, transient=True) as bar:
                    task = bar.add_task("moving", total=1.0)
                    session.move_to(q_goal, speed=options.speed,
                                    progress=lambda s, t=task, b=bar: b.update(t, completed=s))
            else:
                _jog(console, session, q_goal)
            with Progress(TextColumn("{task.description}"), BarColumn(), TimeElapsedColumn(),
                          console=console, transient=True) as bar:
                task = bar.add_task("waiting for stillness", total=1.0)

                def progress(what: str, s: float, t=task, b=bar) -> None:
                    b.update(t, description=what if what == "sampling" else f"waiting for stillness: {what}",
                             completed=s)

                result = take_sample(session, gate, sample_s, progress=progress)
            for r in result.rejected:
                console.print(f"  [yellow]{r}[/]")
            if result.sample is None:
                console.print(f"  [red]pose {k} skipped: no still sample[/]")
                continue
            err = np.abs(result.sample.q - q_goal).max()
            console.print(f"  sampled {result.sample.n} F/T frames, still (joint speed <= "
                          f"{result.sample.qd_max:.3f} rad/s), {np.degrees(err):.2f} deg from the plan")
            samples.append(result.sample)
            used.append(result.sample.q)
            if result.sim_t is not None:
                sim_times.append(float(np.mean(result.sim_t)))
        if not samples:
            console.print("[red]no pose could be sampled[/]")
            return 1
        fit = identifier.fit(samples)
        truth = None
        if sim:
            tb = session.truth_bias(float(np.mean(sim_times)) if sim_times else 0.0)
            truth = {"mass": payload.mass, "com": list(payload.com), "force_bias": tb[:3].tolist(),
                     "torque_bias": tb[3:].tolist()}
        console.print(results_table(fit, truth))
        console.print(f"residual RMS (pose means): {np.array2string(fit.residual_rms, precision=4)}; "
                      f"condition number {fit.condition_number:.3g}")
        colour = {"good": "green", "poorly_excited": "yellow", "inconsistent": "red"}[fit.verdict]
        console.print(f"verdict: [bold {colour}]{fit.verdict}[/]")
        for r in fit.reasons:
            console.print(f"  - {r}")
        cal = calibration_from_fit(fit, scene, session.sensor_serial, np.array(used), n_samples)
        if _ask(console, interactive, f"Save the calibration to {out}?"):
            try:
                save_calibration(cal, out)
            except (OSError, CalibrationError) as exc:
                console.print(f"[red]cannot save {out}: {exc}[/]")
                return 1
            console.print(f"saved {out}")
            if options.plot:
                plot_beside(out, lambda: draw_calibration(fit, scene.name), console)
        if options.json_path is not None:
            options.json_path.write_text(json.dumps(json_record(fit, truth), indent=2))
            console.print(f"wrote {options.json_path}")
        return 0 if fit.verdict == "good" else 3
    except (SessionError, DeviceError) as exc:
        console.print(f"[red]device failure:[/] {exc}")
        return 1
    finally:
        session.close()


def _jog(console: Console, session, q_goal: np.ndarray) -> None:
    """A person jogs the arm: show the live joint error until it is within tolerance and held."""
    console.print("jog the arm to this pose (teach pendant); the error updates live")
    held_since = None
    with Live(console=console, refresh_per_second=10, transient=True) as live:
        while True:
            err = pose_error(session, q_goal)
            t = Table(title="joint error (deg)")
            for j in range(len(err)):
                t.add_column(f"q{j + 1}", justify="right")
            t.add_row(*(f"[{'green' if abs(e) < JOG_TOLERANCE else 'red'}]{np.degrees(e):+7.2f}[/]" for e in err))
            live.update(t)
            if np.abs(err).max() < JOG_TOLERANCE:
                held_since = held_since or time.monotonic()
                if time.monotonic() - held_since > 0.5:
                    return
            else:
                held_since = None
            time.sleep(0.1)
