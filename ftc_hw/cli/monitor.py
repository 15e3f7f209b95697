"""``ftc monitor``: the scene's devices (or their emulators), the live contact monitor, events, recording."""
from __future__ import annotations

from pathlib import Path

import typer

from ftc_hw.app.monitor.config import MonitorConfig, MonitorOutcome, MonitorSetupError
from ftc_hw.app.monitor.session import run_monitor
from ftc_hw.app.monitor.view import make_console
from ftc_hw.app.web.feed import RATE_HZ, WebOptions
from ftc_hw.sim_devices.world import SCENARIOS


def run_monitor_command(scene: str, sim: bool, scenario: str, seed: int, duration: float | None,
                        calibration: Path | None, record: Path | None, reflex: str | None, events: Path | None,
                        truth: Path | None, noise: bool, view: str | bool, level: str = "dynamics",
                        faults: tuple[str, ...] = (), *, device_overrides: tuple[str, ...] = (),
                        rig: Path | None = None, reality: str = "ideal", refine: bool = False,
                        remote: str | None = None, remote_name: str | None = None,
                        zenoh_config: Path | None = None, readers: str = "auto",
                        web_page: tuple[str, int, float] = ("127.0.0.1", 8080, RATE_HZ),
                        resume_after: float | None = None) -> int:
    if truth is not None and not sim:
        typer.echo("error: --truth needs --sim (the ground truth comes from the simulated world)", err=True)
        return 2
    if refine and calibration is None:
        typer.echo("error: --refine needs --calibration (a file with an identification: ftc identify)", err=True)
        return 2
    if resume_after is not None and not sim:
        typer.echo("error: --resume-after needs --sim (the emulated controller's operator resumes the arm)", err=True)
        return 2
    if faults and not sim:
        typer.echo("error: --fault needs --sim (faults are played on the emulated devices)", err=True)
        return 2
    if sim and scenario not in SCENARIOS:
        typer.echo(f"error: unknown scenario {scenario!r} (known: {', '.join(SCENARIOS)})", err=True)
        return 2
    cfg = MonitorConfig(scene, sim=sim, scenario=scenario, seed=seed, duration=duration, calibration=calibration,
                        record=record, reflex=reflex, events=events, truth=truth, noise=noise,
                        view=view in (True, "terminal"), web=web_options(view, web_page),
                        level=None if level == "scene" else level, faults=faults,
                        device_overrides=device_overrides, rig=rig, reality=reality, refine=refine,
                        remote=remote, remote_rig=remote_name, zenoh_config=zenoh_config, readers=readers,
                        resume_after_s=resume_after)
    out = run_guarded(cfg, make_console())
    return out if isinstance(out, int) else out.exit_code


def web_options(view: str | bool, page: tuple[str, int, float]) -> WebOptions | None:
    """``page``: host, port, updates a second."""
    return WebOptions(*page) if view == "web" else None


def run_guarded(cfg: MonitorConfig, console) -> MonitorOutcome | int:
    """``run_monitor`` with setup errors and Ctrl-C turned into exit codes (1, 130)."""
    try:
        return run_monitor(cfg, console)
    except MonitorSetupError as exc:
        typer.echo(f"error: {exc}", err=True)
        return 1
    except KeyboardInterrupt:
        typer.echo("interrupted", err=True)
        return 130
