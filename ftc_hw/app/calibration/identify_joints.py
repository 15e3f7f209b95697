"""``ftc identify`` for an arm sensed through its joints (motor currents, joint torque sensors; a scene
whose sensing has no base F/T sensor): free motion from a recording's joint frames, or from the
emulated arm alone (``--sim``), fitted by :mod:`ftc_hw.calibration.joint_ident` into the calibration
file's identification section."""
from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console

from ftc_hw.app.setup.rig import build_rig, require_device
from ftc_hw.bus import Bus, JointFrame, joints_topic
from ftc_hw.calibration.file import Calibration, Identification, now_iso
from ftc_hw.calibration.free_motion import IdentificationError
from ftc_hw.calibration.joint_ident import JointIdentFit, JointIdentifier
from ftc_hw.calibration.joint_motion import JointMotionData
from ftc_hw.model import ArmModel
from ftc_hw.pipeline import Corrections
from ftc_hw.record.reader import Recording
from ftc_hw.scene import Scene
from ftc_hw.sim_devices.host import WorldHost

SETTLE_S = 0.5  # s the emulated arm holds its start before the scenario goes
DONE_MARGIN_S = 30.0  # s past the scenario's end before giving up on the world's report


def joint_kinds(scene: Scene) -> tuple[str, ...]:
    """The joint signals the scene's sensing uses."""
    return tuple(k for k in ("currents", "joint_torques") if k in scene.sensing.kinds)


def uses_joints(scene: Scene) -> bool:
    """Whether ``ftc identify`` fits this scene from its joints: it uses no base F/T sensor."""
    return scene.sensing.ft != "base"


def frames_to_motion(frames: list[JointFrame], scene: Scene) -> JointMotionData:
    """Joint frames as one stretch of motion: the device's clock where it sends one (an arm controller's
    cycle stamps: steadier than the host's arrival times), else the host's."""
    device = all(f.t_device_ns is not None for f in frames)
    t = np.array([(f.t_device_ns if device else f.t_host_ns) for f in frames], dtype=np.int64)
    t = (t - t[0]) * 1e-9 if len(t) else t.astype(float)
    n = scene.n_joints
    tau = None
    if scene.sensing.joint_torques:
        tau = np.array([f.tau if f.tau is not None else np.full(n, np.nan) for f in frames]).reshape(-1, n)
    return JointMotionData(t, np.array([f.q for f in frames]).reshape(-1, n),
                           np.array([f.qd for f in frames]).reshape(-1, n),
                           np.array([f.current for f in frames]).reshape(-1, n) if scene.sensing.currents else None,
                           tau)


def joint_segments(rec: Recording, scene: Scene, cut_spans: list[tuple[int, int]]) -> tuple[list[JointMotionData],
                                                                                               dict[str, int]]:
    """A recording's joint frames (``joints/<arm>``) as stretches of free motion, split where ``cut_spans``
    (host ns: contacts, lost streams) cut them."""
    frames = [m.frame for m in rec.messages if m.topic.startswith("joints/")]
    if not frames:
        raise IdentificationError(f"{rec.path}: no joint frames (joints/<arm>) recorded")
    t = np.array([f.t_host_ns for f in frames], dtype=np.int64)
    cut = np.zeros(len(frames), dtype=bool)
    for a, b in cut_spans:
        cut |= (t >= a) & (t <= b)
    out, start = [], 0
    for stop in [*np.flatnonzero(cut).tolist(), len(frames)]:
        if stop - start > 1:
            out.append(frames_to_motion(frames[start:stop], scene))
        start = stop + 1
    return out, {"frames": len(frames), "cut": int(cut.sum())}


def record_joint_motion(scene: Scene, scenario: str, duration: float, seed: int, reality: str,
                        console: Console, timeout: float = 30.0) -> tuple[list[JointMotionData], dict[str, int]]:
    """The scene's arm alone emulated (no F/T sensor needed): ``scenario`` played for ``duration`` s,
    its joint frames as the adapter publishes them."""
    arm = require_device(scene, "arm")
    console.print(f"recording {duration:g} s of [cyan]{scenario}[/] on the emulated arm ({arm.name}: {arm.kind}, "
                  f"reality {reality}) ...")
    bus = Bus()
    sub = bus.subscribe(joints_topic(arm.name), maxsize=None)
    world = WorldHost(scene, scenario, devices=[arm.name], duration=duration, seed=seed, reality=reality,
                      preroll=True)
    world.start()
    rig = None
    try:
        rig = build_rig(scene, bus=bus, devices=[arm], endpoints=world.endpoints)
        rig.open().wait(timeout, data=True)
        time.sleep(SETTLE_S)
        sub.drain()
        world.go()
        frames: list[JointFrame] = []
        end = time.monotonic() + duration + DONE_MARGIN_S
        while not world.done and time.monotonic() < end:
            time.sleep(0.05)
            frames += sub.drain()
        frames += sub.drain()
    finally:
        if rig is not None:
            rig.close()
        world.close()
    if len(frames) < 2:
        raise IdentificationError(f"the emulated arm published {len(frames)} joint frames")
    return [frames_to_motion(frames, scene)], {"frames": len(frames), "cut": 0}


def identify_joints(scene: Scene, segments: list[JointMotionData], base: Calibration | None,
                    source: str) -> tuple[Calibration, JointIdentFit]:
    """Fit the joint model on top of ``base`` (its payload and extras; its earlier identification is
    replaced, not added to) and return the updated calibration."""
    c = dataclasses.replace(base, identification=None).corrections(scene) if base is not None else Corrections()
    arm = ArmModel(scene, c.payload, c.inertials)
    identifier = JointIdentifier(arm)
    fit = identifier.fit(segments)
    joints = {"torque_constant": fit.torque_constant, "friction_viscous": np.maximum(fit.friction_viscous, 0.0),
              "friction_coulomb": np.maximum(fit.friction_coulomb, 0.0)}
    if "currents" in fit.kinds:
        joints["rotor_inertia"] = fit.rotor_inertia
    if "joint_torques" in fit.kinds:
        joints["torque_offset"] = fit.offset
    cov, cov_joints = joint_covariance(fit, identifier.kt0)
    ident = Identification(now_iso(), source, fit.verdict, list(fit.reasons), np.eye(6),
                           {b: d for b, d in zip(fit.bodies, fit.delta_pi, strict=True)}, list(fit.untold),
                           _figures(fit), joints, cov, False, None,
                           ",".join(fit.kinds), dict(fit.residual_std), dict(fit.noise_std), cov_joints)
    if base is None:
        cal = Calibration(scene=scene.name, sensor_serial=None, date=now_iso(), bias=np.zeros(6), payload=None,
                          verdict=fit.verdict, reasons=list(fit.reasons), identification=ident)
    else:
        cal = dataclasses.replace(base, identification=ident)
    return cal, fit


def joint_covariance(fit: JointIdentFit, kt0: np.ndarray) -> tuple[np.ndarray, tuple[str, ...]]:
    """The fit's whole covariance in the units the corrections hold (the torque constants' relative scale
    taken to N m/A through the scene's ``kt0``), and the per-joint terms it holds after the bodies'. The
    joint terms stay: the currents cannot tell a common scale of the torque constants and the inertials,
    so the inertials alone look far less certain than the torques they predict from the currents."""
    keys = tuple(k for kind, ks in (("currents", ("torque_constant", "friction_viscous", "friction_coulomb",
                                                  "rotor_inertia")), ("joint_torques", ("torque_offset",)))
                 if kind in fit.kinds for k in ks)
    scale = np.ones(fit.cov.shape[0])
    if "currents" in fit.kinds:
        col = 10 * len(fit.bodies)
        scale[col:col + kt0.size] = kt0
    return fit.cov * np.outer(scale, scale), keys


def _figures(fit: JointIdentFit) -> dict[str, Any]:
    return {"samples": fit.samples, "dropped_rows": fit.dropped_rows, "sensing": list(fit.kinds),
            "parameters": fit.labels, "std": fit.std.tolist(), "prior_std": fit.prior_std.tolist(),
            "joint_std": fit.joint_std().tolist(), "unidentifiable": list(fit.unidentifiable),
            "scale_std": fit.scale_std,
            "joint_residual_std_before_Nm": {k: v.tolist() for k, v in fit.residual_std_before.items()},
            "joint_residual_std_Nm": {k: v.tolist() for k, v in fit.residual_std.items()}}


def report_joints(console: Console, scene: Scene, fit: JointIdentFit, counts: dict[str, int],
                  segments: list[JointMotionData], out: Path, updated: bool) -> None:
    seconds = sum(float(s.t[-1] - s.t[0]) for s in segments if len(s.t))
    console.print(f"free motion from the joints ({', '.join(fit.kinds)}): {seconds:.1f} s in {len(segments)} "
                  f"stretches ({fit.samples} samples; {fit.dropped_rows} rows not finite or out of order left out); "
                  f"frames cut {counts.get('cut', 0)} of {counts.get('frames', 0)}")
    r = scene.robot
    for kind in fit.kinds:
        pairs = zip(r.joints, fit.residual_std_before[kind], fit.residual_std[kind], strict=True)
        console.print(f"residual std ({kind}), model -> identified: "
                      + ", ".join(f"{j} {b:.3g} -> {a:.3g}" for j, b, a in pairs) + " (N m)")
    for j, name in enumerate(r.joints):
        line = f"  {name}:"
        if "currents" in fit.kinds:
            line += (f" torque constant {fit.torque_constant[j]:.4g} N m/A (scene {r.torque_constant[j]:.4g}), viscous "
                     f"{fit.friction_viscous[j]:.3g} N m s/rad ({r.friction_viscous[j]:.3g}), Coulomb "
                     f"{fit.friction_coulomb[j]:.3g} N m ({r.friction_coulomb[j]:.3g})")
        if "joint_torques" in fit.kinds:
            line += f" torque sensor offset {fit.offset[j]:+.3g} N m"
        console.print(line)
    colour = "green" if fit.verdict == "good" else "yellow"
    console.print(f"verdict: [{colour}]{fit.verdict}[/]" + "".join(f"\n  - {x}" for x in fit.reasons))
    if fit.untold:
        console.print(f"  not told by this motion: {', '.join(fit.untold[:12])}"
                      + (f", ... ({len(fit.untold)} in all)" if len(fit.untold) > 12 else ""))
    console.print(f"{'updated' if updated else 'wrote'} {out} (identification from the joints); ftc monitor "
                  f"--calibration {out} applies it")
