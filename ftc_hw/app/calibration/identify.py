"""``ftc identify``: the arm's inertial parameters and the sensor's linear error on the arm's loads,
from contact-free motion, into the calibration file (:mod:`ftc_hw.calibration.free_motion`).

From a recording (``ftc monitor --record``): the pipeline's inputs, with the contacts it reported,
the lost streams and the interpolated-over-gap frames cut out (``--keep-contacts`` keeps the
contacts and leaves them to the fit's robust weights). With ``--sim``: the scene's emulated devices
run a contact-free scenario (the ordinary ``sweep``, or ``excitation``, a planned motion) recorded
through the same monitor, then identified the same way. A scene sensed through its joints (no base
F/T sensor in its sensing) is identified from its joint frames instead (:mod:`.identify_joints`).

Exit codes: 0 identified (verdict good), 4 identified but poorly excited (the file is written; the
verdict names what the motion could not tell), 1 nothing usable, 2 bad arguments.
"""
from __future__ import annotations

import dataclasses
import json
import tempfile
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console

from ftc_hw.app.monitor.config import MonitorOptions, MonitorSetupError, SimOptions, ViewOptions
from ftc_hw.app.monitor.replay_csv import is_mcap
from ftc_hw.app.monitor.session import run_monitor
from ftc_hw.app.ros.bag_form import is_ros_bag
from ftc_hw.app.setup.rig import RigError
from ftc_hw.bus import EVENTS_CONTACT, EVENTS_DEVICE
from ftc_hw.calibration.applied import merge_inertials
from ftc_hw.calibration.excitation import plan_excitation
from ftc_hw.calibration.file import (
    Calibration,
    CalibrationError,
    Identification,
    load_calibration,
    now_iso,
    save_calibration,
)
from ftc_hw.calibration.free_motion import FreeMotionFit, FreeMotionIdentifier, IdentificationError, MotionData
from ftc_hw.calibration.joint_friction import JointFit, fit_joint_friction
from ftc_hw.calibration.joint_motion import JointMotionData, noise_std
from ftc_hw.devices.base import DeviceError
from ftc_hw.devices.registry import moves_on_goals, role_of
from ftc_hw.model import ArmModel
from ftc_hw.monitor import MONITOR_INPUT
from ftc_hw.pipeline import Corrections
from ftc_hw.record.reader import Recording, RecordingError, read_recording
from ftc_hw.record.ur_csv import read_ur_csv
from ftc_hw.scene import Scene
from ftc_hw.sim_devices.host import WorldHostError

from .device_session import DeviceSession, SessionError
from .drive_excitation import drive_excitation
from .fit_figure import plot_beside
from .identify_bag import bag_ft_motion, bag_joint_motion
from .identify_joints import identify_joints, joint_segments, record_joint_motion, report_joints, uses_joints
from .identify_plot import draw_identification

CONTACT_MARGIN_S = 0.3  # cut this much before a reported contact and after its end
MIN_SEGMENT_S = 0.5
MAX_JOINT_GAP_NS = 20_000_000  # a longer joint gap is cut; shorter ones the low pass spans
FREE_SCENARIOS = ("sweep", "excitation", "hold")


@dataclass
class IdentifyOptions:
    out: Path | None = None  # None: calibration-<scene>.toml
    calibration: Path | None = None  # the file to start from (default: ``out`` if it exists)
    json_path: Path | None = None
    keep_contacts: bool = False
    gain: bool = True
    plot: bool = True  # the fit drawn to a PNG beside ``out``
    topics: Path | None = None  # a ROS 2 bag's topic map (None: the drivers' defaults for the scene)


def motion_segments(rec: Recording, keep_contacts: bool = False) -> tuple[list[MotionData], dict[str, int]]:
    """The recording's stretches of free motion, and how many frames each rule cut."""
    frames = [m.frame for m in rec.messages if m.topic == MONITOR_INPUT]
    if not frames:
        raise IdentificationError(f"{rec.path}: no {MONITOR_INPUT} messages (record with ftc monitor --record)")
    cut = np.zeros(len(frames), dtype=bool)
    t = np.array([f.t_host_ns for f in frames], dtype=np.int64)
    counts = {"frames": len(frames), "contact": 0, "stream_lost": 0, "joint_gap": 0, "saturated": 0, "tare": 0}
    spans = _spans(rec, "contact") if not keep_contacts else []
    for name, rule in (("contact", spans), ("stream_lost", _spans(rec, "lost"))):
        for a, b in rule:
            inside = (t >= a) & (t <= b) & ~cut
            counts[name] += int(inside.sum())
            cut |= inside
    flags = (("joint_gap", [f.joint_gap_ns > MAX_JOINT_GAP_NS for f in frames]),
             ("saturated", [f.saturated for f in frames]), ("tare", [f.tare for f in frames]))
    for name, flag in flags:
        f = np.array(flag) & ~cut
        counts[name] = int(f.sum())
        cut |= f
    return _split(frames, t, cut), counts


def _spans(rec: Recording, what: str) -> list[tuple[int, int]]:
    """(start, end) host ns of each reported contact (with margins) or lost stream."""
    margin = int(CONTACT_MARGIN_S * 1e9)
    out, open_at = [], {}
    for m in rec.messages:
        ev = m.frame
        if what == "contact" and m.topic == EVENTS_CONTACT:
            if ev.kind == "onset":
                open_at[ev.contact_id] = ev.t_host_ns - margin
            elif ev.kind == "offset":
                out.append((open_at.pop(ev.contact_id, ev.t_host_ns - margin), ev.t_host_ns + margin))
        elif what == "lost" and m.topic == EVENTS_DEVICE and ev.kind.endswith(("_lost", "_back")):
            stream = ev.kind.split("_")[0]
            if ev.kind.endswith("_lost"):
                open_at[stream] = ev.t_host_ns - margin
            else:
                out.append((open_at.pop(stream, ev.t_host_ns - margin), ev.t_host_ns + margin))
    end = rec.messages[-1].log_time if rec.messages else 0
    out += [(a, max(end, a) + margin) for a in open_at.values()]  # still open at the end
    return out


def _split(frames: list, t: np.ndarray, cut: np.ndarray) -> list[MotionData]:
    dt = np.diff(t)
    step = float(np.median(dt)) if len(dt) else 1.0
    breaks = np.flatnonzero(cut | np.r_[False, dt > 3 * step])
    out, start = [], 0
    for stop in [*breaks.tolist(), len(frames)]:
        seg = []
        for k in range(start, stop):  # strictly increasing times: a repeated stamp would divide by zero
            if not cut[k] and (not seg or t[k] > t[seg[-1]]):
                seg.append(k)
        start = stop + (1 if stop < len(frames) and cut[stop] else 0)
        if len(seg) < 2 or (t[seg[-1]] - t[seg[0]]) * 1e-9 < MIN_SEGMENT_S:
            continue
        out.append(MotionData(t[seg] * 1e-9, np.array([frames[k].wrench for k in seg]),
                              np.array([frames[k].q for k in seg]), np.array([frames[k].qd for k in seg]),
                              np.array([frames[k].current for k in seg])))
    return out


def base_calibration(scene: Scene, opts: IdentifyOptions) -> Calibration | None:
    """The calibration to start from: ``--calibration``, else ``--out`` if it exists."""
    path = opts.calibration or (opts.out if opts.out.exists() else None)
    return None if path is None else load_calibration(path, scene=scene)


def identify(scene: Scene, segments: list[MotionData], base: Calibration | None, source: str,
             gain: bool = True) -> tuple[Calibration, FreeMotionFit]:
    """Fit on top of ``base`` (its payload, corrections and frame) and return the updated calibration."""
    c = base.corrections(scene) if base is not None else Corrections()
    model_scene = scene if c.gravity is None else dataclasses.replace(scene, gravity=c.gravity)
    arm = ArmModel(model_scene, c.payload, c.inertials)
    frame = c.frame
    if frame is not None:  # fit in the model's sensor frame
        inv = np.linalg.inv(frame)
        segments = [dataclasses.replace(s, wrench=s.wrench @ inv.T) for s in segments]
    fit = FreeMotionIdentifier(arm, gain=gain).fit(segments)
    joints = _joints(arm, fit, segments)
    ident = Identification(now_iso(), source, fit.verdict, list(fit.reasons), fit.gain,
                           {b: d for b, d in zip(fit.bodies, fit.delta_pi, strict=True)}, list(fit.untold),
                           {"samples": fit.samples, "residual_rms_before": fit.residual_rms_before.tolist(),
                            "residual_rms": fit.residual_rms.tolist(),
                            "parameters": fit.labels, "std": fit.std.tolist(), "prior_std": fit.prior_std.tolist(),
                            **({} if joints is None else _joint_figures(joints))},
                           {} if joints is None else {"torque_constant": joints.torque_constant,
                                                      "friction_viscous": joints.friction_viscous,
                                                      "friction_coulomb": joints.friction_coulomb},
                           fit.cov[6:, 6:].copy(), gain, fit.told_gain(),
                           "base_ft" if joints is None else "base_ft,currents",
                           {} if joints is None else {"currents": joints.residual_rms},
                           {} if joints is None else noise_std(segments, ("currents",), joints.torque_constant))
    bias = fit.bias if frame is None else frame @ fit.bias
    if base is None:
        cal = Calibration(scene=scene.name, sensor_serial=None, date=now_iso(), bias=bias, payload=None,
                          verdict=fit.verdict, reasons=list(fit.reasons), identification=ident)
    else:
        cal = dataclasses.replace(base.with_bias(bias), identification=ident)
    return cal, fit


def _joints(arm: ArmModel, fit: FreeMotionFit, segments: list[MotionData]) -> JointFit | None:
    """Joint friction and torque constants with the identified model, when the currents were recorded."""
    if any(s.current is None or not np.any(s.current) for s in segments):
        return None
    model = ArmModel(arm.scene, arm.payload, merge_inertials(arm.inertials, dict(zip(fit.bodies, fit.delta_pi,
                                                                                        strict=True))))
    return fit_joint_friction(model, segments)


def _joint_figures(j: JointFit) -> dict[str, Any]:
    untold = j.untold if j.untold is not None else [False] * len(j.fitted)
    return {"joints_fitted": j.fitted.tolist(), "joints_untold": [bool(u) for u in untold],
            "joint_residual_rms_before_Nm": j.residual_rms_before.tolist(),
            "joint_residual_rms_Nm": j.residual_rms.tolist(), "joint_std": j.std.tolist()}


def run_identify(scene: Scene, recording: Path | Sequence[Path] | None, opts: IdentifyOptions, *, sim: bool = False,
                 scenario: str = "sweep", duration: float = 120.0, seed: int = 0, reality: str = "ideal",
                 console: Console | None = None, drive: bool = False) -> int:
    """From ``recording`` (one or several: MCAP, or a UR recording's CSV for a scene sensed through its
    joints); or ``sim``: the emulated devices run ``scenario`` (recorded); or ``drive``: the planned
    excitation streamed to the arm as goals through its protocol (emulated with ``sim``)."""
    console = console or Console()
    if opts.out is None:
        opts = dataclasses.replace(opts, out=Path(f"calibration-{scene.name}.toml"))
    recordings = [recording] if isinstance(recording, Path) else list(recording or [])
    if uses_joints(scene):
        return _run_joint_identify(scene, recordings, opts, sim=sim, scenario=scenario, duration=duration, seed=seed,
                                   reality=reality, console=console, drive=drive)
    bags = bool(recordings) and all(is_ros_bag(p) for p in recordings)
    if not bags and (len(recordings) > 1 or (recordings and not is_mcap(recordings[0]))):
        console.print("[red]cannot identify:[/] the F/T sensor's readings come from one MCAP recording (a UR "
                      "recording holds no base F/T sensor: --sensing currents identifies the arm from its joints)")
        return 1
    recording = recordings[0] if recordings else None
    try:
        base = base_calibration(scene, opts)
        if drive:
            segments, counts = _driven(scene, duration, seed, sim, reality, console)
            source = (f"ftc identify --plan, driven through the arm's protocol: {duration:g} s, seed {seed}"
                      + (f", emulated, reality {reality}" if sim else ""))
        elif bags:
            segments, counts = bag_ft_motion(scene, recordings, opts.topics, console)
            source = ", ".join(str(p) for p in recordings)
        else:
            with tempfile.TemporaryDirectory(prefix="ftc-identify-") as tmp:
                if sim:
                    recording = _record_sim(scene, scenario, duration, seed, reality, Path(tmp) / "run.mcap",
                                            console)
                rec = read_recording(recording)
                segments, counts = motion_segments(rec, keep_contacts=opts.keep_contacts or sim)
            source = (f"ftc identify --sim: {scenario}, {duration:g} s, reality {reality}, seed {seed}" if sim
                      else str(recording))
        cal, fit = identify(scene, segments, base, source, gain=opts.gain)
    except (IdentificationError, RecordingError, CalibrationError, MonitorSetupError, SessionError, RigError,
            DeviceError, OSError, np.linalg.LinAlgError) as exc:
        console.print(f"[red]cannot identify:[/] {exc}")
        return 1
    try:
        save_calibration(cal, opts.out)
    except (OSError, CalibrationError) as exc:
        console.print(f"[red]cannot save {opts.out}: {exc}[/]")
        return 1
    _report(console, fit, counts, segments, opts.out, base is not None)
    _report_joints(console, scene, cal.identification)
    if opts.plot:
        plot_beside(opts.out, lambda: draw_identification(fit, cal.identification, scene), console)
    if opts.json_path is not None:
        figures = _figures(fit, counts, segments) | {"joints": {k: v.tolist() for k, v in
                                                                 cal.identification.joints.items()}}
        opts.json_path.write_text(json.dumps(figures, indent=2))
    return 0 if fit.verdict == "good" else 4


def _run_joint_identify(scene: Scene, recordings: list[Path], opts: IdentifyOptions, *, sim: bool, scenario: str,
                        duration: float, seed: int, reality: str, console: Console, drive: bool) -> int:
    """:func:`run_identify` for a scene sensed through its joints. The planned excitation is played by the
    emulated world (a real arm's controller plays ``--plan-file`` while ``ftc monitor --record`` runs)."""
    try:
        if drive and not sim:
            raise SessionError("a scene sensed through its joints is identified from a recording here: play the "
                               "plan (--plan-file) on the arm while ftc monitor --record runs")
        base = base_calibration(scene, opts)
        if sim:
            scenario = "excitation" if drive else scenario
            if scenario not in FREE_SCENARIOS:
                raise IdentificationError(f"--scenario {scenario}: identification needs free motion "
                                          f"({', '.join(FREE_SCENARIOS)})")
            segments, counts = record_joint_motion(scene, scenario, duration, seed, reality, console)
            source = f"ftc identify --sim: {scenario}, {duration:g} s, reality {reality}, seed {seed}, joints"
        else:
            segments, counts = _recorded_joint_motion(scene, recordings, opts, console)
            source = ", ".join(str(p) for p in recordings)
        cal, fit = identify_joints(scene, segments, base, source)
        save_calibration(cal, opts.out)
    except (IdentificationError, RecordingError, CalibrationError, SessionError, RigError, DeviceError, OSError,
            WorldHostError, np.linalg.LinAlgError) as exc:
        console.print(f"[red]cannot identify:[/] {exc}")
        return 1
    report_joints(console, scene, fit, counts, segments, opts.out, base is not None)
    if opts.json_path is not None:
        opts.json_path.write_text(json.dumps({"verdict": fit.verdict, "reasons": fit.reasons, "untold": fit.untold,
                                              **cal.identification.figures,
                                              "joints": {k: v.tolist() for k, v in cal.identification.joints.items()}},
                                             indent=2))
    return 0 if fit.verdict == "good" else 4


def _recorded_joint_motion(scene: Scene, recordings: list[Path], opts: IdentifyOptions,
                           console: Console) -> tuple[list, dict[str, int]]:
    """The free motion of every recording: an MCAP's joint frames (contacts and lost streams cut), a UR
    recording's kept rows, a ROS 2 bag's kept joint states (what each holds said first)."""
    segments, counts = [], Counter()
    for path in recordings:
        if is_ros_bag(path):
            more, n = bag_joint_motion(scene, path, opts.topics, console)
        elif is_mcap(path):
            rec = read_recording(path)
            spans = _spans(rec, "lost") + ([] if opts.keep_contacts else _spans(rec, "contact"))
            more, n = joint_segments(rec, scene, spans)
        else:
            ur = read_ur_csv(path)
            console.print(ur.summary())
            if "currents" in scene.sensing.kinds and ur.current is None:
                raise RecordingError(f"{path}: no actual_current column: the scene is identified from its "
                                     "motor currents")
            if ur.n_joints != scene.n_joints:
                raise RecordingError(f"{path}: {ur.n_joints} joints recorded, scene {scene.name!r} has "
                                     f"{scene.n_joints}")
            more, n = [JointMotionData(ur.t, ur.q, ur.qd, current=ur.current)], {"frames": len(ur.t), "cut": 0}
        segments += more
        counts.update(n)
    return segments, dict(counts)


def run_planned_identify(scene: Scene, opts: IdentifyOptions, *, sim: bool, duration: float, seed: int,
                         reality: str, console: Console | None = None) -> int:
    """The planned excitation: streamed as goals where the arm's protocol takes them (DYNAMIXEL; emulated
    with ``sim``), else played by the emulated world (``sim``); raises ``SessionError`` for a real arm that
    takes no goals (its controller plays ``ftc identify --plan-file``)."""
    arm = next((d for d in scene.devices if role_of(d.kind) == "arm"), None)
    if arm is not None and moves_on_goals(arm.kind):
        return run_identify(scene, None, opts, sim=sim, duration=duration, seed=seed, reality=reality,
                            console=console, drive=True)
    if not sim:
        raise SessionError(f"the planned excitation is driven only on an arm that takes goal positions "
                           f"(DYNAMIXEL); {arm.kind if arm else 'no arm'} here: write it with --plan-file for "
                           "the controller")
    return run_identify(scene, None, opts, sim=True, scenario="excitation", duration=duration, seed=seed,
                        reality=reality, console=console)


def _driven(scene: Scene, duration: float, seed: int, sim: bool, reality: str,
            console: Console) -> tuple[list[MotionData], dict[str, int]]:
    plan = plan_excitation(scene, duration, seed=seed)
    console.print(f"playing {duration:g} s of the planned excitation through the arm's protocol"
                  + (f" (emulated devices, reality {reality})" if sim else "") + " ...")
    with DeviceSession(scene, sim=sim, seed=seed, reality=reality) as session:
        if not session.arm.moves_on_goals:
            raise SessionError(f"{session.arm.describe()} takes no goal positions: write the plan with "
                               "--plan-file and play it on the controller while ftc monitor --record runs")
        return drive_excitation(session, plan.excitation, motion_segments)


def _record_sim(scene: Scene, scenario: str, duration: float, seed: int, reality: str, path: Path,
                console: Console) -> Path:
    if scenario not in FREE_SCENARIOS:
        raise IdentificationError(f"--scenario {scenario}: identification needs free motion "
                                  f"({', '.join(FREE_SCENARIOS)})")
    console.print(f"recording {duration:g} s of [cyan]{scenario}[/] on the emulated devices (reality {reality}) ...")
    cfg = MonitorOptions(str(scene.path), sim=True, world=SimOptions(scenario, seed, reality), duration=duration,
                         record=path, view=ViewOptions("none"), title="ftc identify", judged=False)
    run_monitor(cfg, console)  # its alarms are the untrained model's: the scenario has no contact
    return path


def _figures(fit: FreeMotionFit, counts: dict[str, int], segments: list[MotionData]) -> dict[str, Any]:
    return {"verdict": fit.verdict, "reasons": fit.reasons, "untold": fit.untold, "samples": fit.samples,
            "segments": len(segments), "seconds": float(sum(s.t[-1] - s.t[0] for s in segments)), "cut": counts,
            "residual_rms_before": fit.residual_rms_before.tolist(), "residual_rms": fit.residual_rms.tolist(),
            "gain": fit.gain.tolist(), "bias": fit.bias.tolist(),
            "inertials": {b: d.tolist() for b, d in zip(fit.bodies, fit.delta_pi, strict=True)}}


def _report_joints(console: Console, scene: Scene, ident: Identification) -> None:
    if not ident.joints:
        console.print("joint friction and torque constants: not fitted (no motor currents recorded)")
        return
    fitted = ident.figures.get("joints_fitted", [])
    untold = ident.figures.get("joints_untold", [])
    r = scene.robot
    for j, name in enumerate(scene.robot.joints):
        if j < len(untold) and untold[j]:
            console.print(f"  {name}: moved, but its motor current did not tell its torque constant from its "
                          "friction (little load but its own friction): the scene's values kept")
            continue
        if not (j < len(fitted) and fitted[j]):
            console.print(f"  {name}: moved too little to fit its friction: the scene's values kept")
            continue
        jt = ident.joints
        console.print(f"  {name}: torque constant {jt['torque_constant'][j]:.3g} N m/A (scene "
                      f"{r.torque_constant[j]:.3g}), viscous {jt['friction_viscous'][j]:.3g} N m s/rad "
                      f"({r.friction_viscous[j]:.3g}), Coulomb {jt['friction_coulomb'][j]:.3g} N m "
                      f"({r.friction_coulomb[j]:.3g})")


def _report(console: Console, fit: FreeMotionFit, counts: dict[str, int], segments: list[MotionData], out: Path,
            updated: bool) -> None:
    seconds = sum(s.t[-1] - s.t[0] for s in segments)
    cuts = ", ".join(f"{k} {v}" for k, v in counts.items() if k != "frames" and v)
    console.print(f"free motion: {seconds:.1f} s in {len(segments)} stretches ({fit.samples} samples); "
                  f"frames cut: {cuts or 'none'} of {counts['frames']}")
    axes = ("fx", "fy", "fz", "tx", "ty", "tz")
    console.print("residual RMS, model -> identified: " + ", ".join(
        f"{a} {b:.3g} -> {c:.3g}" for a, b, c in zip(axes, fit.residual_rms_before, fit.residual_rms, strict=True))
        + " (N, N m)")
    colour = "green" if fit.verdict == "good" else "yellow"
    console.print(f"verdict: [{colour}]{fit.verdict}[/]" + ("".join(f"\n  - {r}" for r in fit.reasons)))
    if fit.untold:
        shown = ", ".join(fit.untold[:12]) + (f", ... ({len(fit.untold)} in all)" if len(fit.untold) > 12 else "")
        console.print(f"  not told by this motion: {shown}")
    console.print(f"{'updated' if updated else 'wrote'} {out} (bias, identification); ftc monitor --calibration "
                  f"{out} applies it")
