"""``ftc demo``: a built-in scene's emulated devices (each in its own process) with a scripted collision
scenario, the monitor's live view, then the detected contacts against the world's ground truth.

In a mismatched world (``--reality typical``, the default, or ``harsh``) the demo does what a user does
on a real arm first: it identifies the drawn arm from a planned excitation on the same emulated devices
(``ftc identify --sim --plan``), then monitors with that calibration. The identification and the
monitor see the same draw (the same seed)."""
from __future__ import annotations

import tempfile
from dataclasses import replace
from pathlib import Path

from rich.console import Console

from ftc_hw.app.calibration.device_session import SessionError
from ftc_hw.app.calibration.identify import IdentifyOptions, run_planned_identify
from ftc_hw.app.monitor.config import DemoOptions, MonitorOutcome
from ftc_hw.app.monitor.session import run_monitor
from ftc_hw.scene import SceneError, load_scene


def run_demo(options: DemoOptions, console: Console) -> MonitorOutcome:
    """Identify the drawn arm first (in a mismatched world, for ``options.identify_s`` s), then the monitor
    run of ``options.monitor`` with that calibration, then the summary. Raises what ``run_monitor`` raises."""
    cfg, identify_s = options.monitor, options.identify_s
    scene_name, scenario, duration, seed = cfg.scene, cfg.world.scenario, cfg.duration, cfg.world.seed
    reality = cfg.world.reality
    identified = reality != "ideal" and identify_s > 0
    console.print(f"[bold]ftc demo[/]: scene [cyan]{scene_name}[/], scenario [cyan]{scenario}[/], reality "
                  f"[cyan]{reality}[/] (seed {seed}), {duration:g} s: "
                  + (f"first the drawn arm identified from {identify_s:g} s of planned excitation, then " if identified
                     else "")
                  + "emulated devices -> adapters -> bus -> compensation, detection, localization; "
                  "then the contacts against ground truth")
    with tempfile.TemporaryDirectory(prefix="ftc-demo-") as tmp:
        calibration, how = None, "the world is the pipeline's own model"
        if identified:
            calibration = _identify(scene_name, identify_s, seed, reality, Path(tmp) / "calibration.toml", console)
            how = (f"a {reality} draw of another arm, identified first" if calibration is not None else
                   f"a {reality} draw of another arm; its identification failed: the nominal model monitored it")
        elif reality != "ideal":
            how = f"a {reality} draw of another arm, not identified (--identify-seconds 0)"
        if reality != "ideal" and calibration is None:
            console.print("[yellow]monitoring the drawn arm with the scene's nominal model: expect the false alarms "
                          "an unidentified arm raises (docs/reality.md)[/]")
        out = run_monitor(replace(cfg, calibration=calibration), console)
    _summary(console, out, scenario, duration, how)
    return out


def _identify(scene_name: str, identify_s: float, seed: int, reality: str, path: Path,
              console: Console) -> Path | None:
    """The calibration file of the drawn arm, or None when it could not be identified (said why)."""
    try:
        scene = load_scene(scene_name)
    except SceneError as exc:
        console.print(f"[red]error:[/] {exc}")
        return None
    console.print(f"[bold]step 1/2[/]: identifying the drawn arm (what [cyan]ftc identify --scene {scene_name} "
                  f"--sim --plan --reality {reality} --seed {seed} --duration {identify_s:g}[/] does)")
    try:
        rc = run_planned_identify(scene, IdentifyOptions(out=path), sim=True, duration=identify_s, seed=seed,
                                  reality=reality, console=console)
    except SessionError as exc:
        console.print(f"[red]cannot identify:[/] {exc}")
        return None
    # 4: poorly excited, the file written with what the motion told (the rest at the model's values)
    if rc not in (0, 4) or not path.is_file():
        return None
    console.print("[bold]step 2/2[/]: the monitor with that calibration ([cyan]ftc monitor --calibration[/])")
    return path


def _summary(console: Console, out: MonitorOutcome, scenario: str, duration: float, world: str) -> None:
    ev = out.evaluation
    if ev is None:
        return
    worst = ev.worst_rms_mm(whole=True)
    ratio = ev.worst_err_over_crlb(whole=True)
    own = ev.worst_err_over_solver(whole=True)
    honest = ev.worst_err_over_std(whole=True)
    cut = [c for c in ev.contacts if c.cut]
    console.print(f"[bold]summary:[/] {world}: {ev.detected}/{len(ev.contacts)} contacts detected, "
                  f"{sum(c.delay_ok for c in ev.contacts)} within {ev.delay_limit_ms:g} ms of their first "
                  f"sample, {len(ev.false_alarms)} false alarms"
                  + (f", worst per-contact RMS point error {worst:.1f} mm" if worst is not None else "")
                  + (f" (worst per-contact RMS of error / Cramer-Rao bound: {ratio:.2f}"
                     + (f"; of error / the solver's own on the true wrench plus sensor noise: {own:.2f}"
                        if own is not None else "")
                     + (f"; of error / the uncertainty it reports: {honest:.2f}" if honest is not None else "")
                     + ")" if ratio is not None else "")
                  + "".join(f"; contact {c.index} was cut by the run's end after {c.trusted} unflagged "
                            f"estimates (not in the worst figures; its row above)" for c in cut)
                  + (f"; [bold red]DEGRADED[/] ({'; '.join(out.degraded)}): read these figures with that in mind"
                     if out.degraded else ""))
    if not ev.contacts:
        console.print(f"[yellow]the world made no contact in this run: scenario {scenario!r} over {duration:g} s "
                      "had nothing to detect, so nothing above was judged[/]")
