"""``ftc monitor``, ``ftc demo`` and ``ftc replay``: the options' checks, the view's options, a run's outcome
as an exit code. The runs are the app's (:mod:`ftc_hw.app.monitor.session`, :mod:`ftc_hw.app.demo`,
:mod:`ftc_hw.app.monitor.replay`)."""
from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

import typer

from ftc_hw.app.monitor.config import MonitorOptions, MonitorSetupError, ReplayOptions, ViewOptions
from ftc_hw.app.monitor.replay import run_replay
from ftc_hw.app.monitor.replay_bag import run_bag_replay
from ftc_hw.app.monitor.replay_csv import is_mcap, run_csv_replay
from ftc_hw.app.monitor.view import make_console
from ftc_hw.app.ros.bag_form import is_ros_bag
from ftc_hw.app.web.feed import WebOptions
from ftc_hw.record.replay import ReplayError
from ftc_hw.sim_devices.world import SCENARIOS

T = TypeVar("T")


def check_monitor(options: MonitorOptions) -> None:
    """Exit code 2, said why, on options that need ``--sim`` without it, or ``--refine`` without a calibration."""
    world = options.world
    for wrong, why in (
            (world.truth is not None and not options.sim,
             "--truth needs --sim (the ground truth comes from the simulated world)"),
            (options.refine and options.calibration is None,
             "--refine needs --calibration (a file with an identification: ftc identify)"),
            (world.resume_after_s is not None and not options.sim,
             "--resume-after needs --sim (the emulated controller's operator resumes the arm)"),
            (bool(world.faults) and not options.sim, "--fault needs --sim (faults are played on the emulated devices)"),
            (world.ahead and not options.sim, "--world-ahead needs --sim (it is how the simulated world runs)"),
            (world.ahead and options.duration is None, "--world-ahead needs --duration (the run is computed first)"),
            (world.ahead and options.reflex == "retreat",
             "--world-ahead plays a computed run: the arm cannot retreat in it (use the live world)"),
            (options.record_format != "ftc" and options.record is None,
             f"--record-format {options.record_format} needs --record PATH"),
            (options.sim and world.scenario not in SCENARIOS,
             f"unknown scenario {world.scenario!r} (known: {', '.join(SCENARIOS)})")):
        if wrong:
            typer.echo(f"error: {why}", err=True)
            raise typer.Exit(2)


def view_options(view: str, host: str, port: int, view_hz: float) -> ViewOptions:
    """``--view`` with the page's ``--host``, ``--port`` and ``--view-hz``."""
    return ViewOptions(view, WebOptions(host, port, view_hz))


def outcome_or_exit(run: Callable[[], T]) -> T:
    """The run's outcome; its setup error (exit code 1) or Ctrl-C (130) said, and the command ended."""
    try:
        return run()
    except MonitorSetupError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(1) from None
    except KeyboardInterrupt:
        typer.echo("interrupted", err=True)
        raise typer.Exit(130) from None


def replay_exit_code(options: ReplayOptions, check: bool) -> int:
    """``ftc replay``: 1 when it cannot read or replay, and with ``check`` when the events differ; else 0.
    A UR recording (not MCAP) or a ROS 2 bag replays through ``--scene``'s monitor; it holds no events to check."""
    try:
        if is_ros_bag(options.recording):
            if check:
                typer.echo("error: --check compares with recorded events: a ROS 2 bag holds none", err=True)
                return 2
            run_bag_replay(options, make_console())
            return 0
        if options.topics is not None:
            typer.echo("error: --topics maps a ROS 2 bag's topics: this is not one", err=True)
            return 2
        if not is_mcap(options.recording):
            if check:
                typer.echo("error: --check compares with recorded events: a UR recording holds none", err=True)
                return 2
            run_csv_replay(options, make_console())
            return 0
        if options.scene is not None or options.sensing is not None:
            typer.echo("error: --scene and --sensing are for UR recordings and ROS 2 bags: an MCAP recording of "
                       "ftc monitor holds its own",
                       err=True)
            return 2
        result = run_replay(options, make_console())
    except (MonitorSetupError, ReplayError, OSError) as exc:
        typer.echo(f"error: {exc}", err=True)
        return 1
    return 1 if check and not result.identical else 0
