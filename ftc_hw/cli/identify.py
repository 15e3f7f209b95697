"""``ftc identify``: arguments to :mod:`ftc_hw.app.calibration.identify`."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import typer

from ftc_hw.app.calibration.device_session import SessionError
from ftc_hw.app.calibration.identify import IdentifyOptions, run_identify, run_planned_identify
from ftc_hw.app.monitor.replay_csv import is_mcap
from ftc_hw.app.monitor.view import make_console
from ftc_hw.app.ros.bag_form import is_ros_bag
from ftc_hw.calibration.excitation import plan_excitation
from ftc_hw.record.reader import RecordingError, read_recording
from ftc_hw.record.replay import ReplayError, recorded_scene
from ftc_hw.scene import Scene, SceneError

from .common import scene_or_exit, sensing_kinds


def run_identify_command(recording: list[Path] | None, scene_name: str | None, *, sim: bool, plan: bool,
                         plan_file: Path | None, scenario: str | None, duration: float, seed: int, reality: str,
                         opts: IdentifyOptions, device_overrides: tuple[str, ...] = (),
                         rig: Path | None = None, sensing: str | None = None) -> int:
    console = make_console()
    if (recording is None) == (not sim and not plan_file and not plan):
        raise typer.BadParameter("give a recording (FILE.mcap), or --sim, --plan or --plan-file",
                                 param_hint="RECORDING")
    recording = recording or None  # typer gives an empty list for none
    if recording is not None and (sim or plan_file or plan):
        raise typer.BadParameter("a recording, or --sim / --plan / --plan-file, not both", param_hint="RECORDING")
    if recording is not None:
        if scene_name is None and any(is_ros_bag(p) or (p.is_file() and not is_mcap(p)) for p in recording):
            raise typer.BadParameter("a UR recording or a ROS 2 bag holds no scene: give --scene (ur10e, ur5e, ...)",
                                     param_hint="--scene")
        scene = scene_or_exit(scene_name) if scene_name else _recorded(recording[0])
        return run_identify(with_sensing(scene, sensing), recording, opts, console=console)
    if scene_name is None:
        raise typer.BadParameter("--sim, --plan and --plan-file need --scene", param_hint="--scene")
    scene = with_sensing(scene_or_exit(scene_name, device_overrides, rig), sensing)
    if plan_file is not None:
        return write_plan(scene, plan_file, duration, seed, console)
    if plan:
        try:
            return run_planned_identify(scene, opts, sim=sim, duration=duration, seed=seed, reality=reality,
                                        console=console)
        except SessionError as exc:
            raise typer.BadParameter(str(exc), param_hint="--plan") from None
    return run_identify(scene, None, opts, sim=True, scenario=scenario or "sweep", duration=duration, seed=seed,
                        reality=reality, console=console)


def with_sensing(scene: Scene, sensing: str | None) -> Scene:
    """``--sensing a,b``: the scene using only those of what it has."""
    if sensing is None:
        return scene
    try:
        return scene.with_sensing(sensing_kinds(sensing))
    except SceneError as exc:
        raise typer.BadParameter(str(exc), param_hint="--sensing") from None


def _recorded(path: Path):
    try:
        return recorded_scene(read_recording(path, topics=set()))
    except (RecordingError, ReplayError, OSError) as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None


def write_plan(scene, path: Path, duration: float, seed: int, console) -> int:
    """The planned excitation as CSV (t s, then q rad per joint at 125 Hz, a UR controller's servoj rate),
    for an arm that takes no commands from here: play it on the controller while ftc monitor --record runs."""
    with console.status("planning the excitation"):
        plan = plan_excitation(scene, duration, seed=seed)
    t, q, _, _ = plan.excitation.samples(125.0)
    header = "t_s," + ",".join(f"{j}_rad" for j in scene.robot.joints)
    np.savetxt(path, np.column_stack([t, q]), delimiter=",", header=header, comments="", fmt="%.6f")
    console.print(f"wrote {path}: {len(t)} samples, {t[-1]:.1f} s, peak joint speed {plan.max_speed:.2f} rad/s, "
                  f"{plan.told} parameter directions told; chosen of {plan.candidates} candidates "
                  f"({plan.rejected['self_collision']} self-colliding)")
    return 0
