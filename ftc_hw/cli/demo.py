"""``ftc demo``: a built-in scene's emulated devices (each in its own process) with a scripted collision
scenario, the monitor's live view, then the detected contacts against the world's ground truth."""
from __future__ import annotations

from pathlib import Path

from ftc_hw.app.session import MonitorConfig
from ftc_hw.app.view import make_console

from .monitor import run_guarded


def run_demo(scene_name: str, scenario: str, duration: float, seed: int, record: Path | None = None,
             reality: str = "ideal") -> int:
    console = make_console()
    console.print(f"[bold]ftc demo[/]: scene [cyan]{scene_name}[/], scenario [cyan]{scenario}[/], reality "
                  f"[cyan]{reality}[/], {duration:g} s: "
                  "emulated devices -> adapters -> bus -> compensation, detection, localization; "
                  "then the contacts against ground truth")
    cfg = MonitorConfig(scene_name, sim=True, scenario=scenario, seed=seed, duration=duration, record=record,
                        title="ftc demo", reality=reality)
    out = run_guarded(cfg, console)
    if isinstance(out, int):
        return out
    ev = out.evaluation
    if ev is not None:
        worst = ev.worst_rms_mm(whole=True)
        ratio = ev.worst_err_over_crlb(whole=True)
        own = ev.worst_err_over_solver(whole=True)
        honest = ev.worst_err_over_std(whole=True)
        cut = [c for c in ev.contacts if c.cut]
        console.print(f"[bold]summary[/]: {ev.detected}/{len(ev.contacts)} contacts detected, "
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
    return out.exit_code
