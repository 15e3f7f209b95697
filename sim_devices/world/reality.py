"""Realities: seeded draws of how a real arm, sensor and shell differ from the scene's model.

``ideal`` is the model itself (plus the scene's own ``[world]`` table, if it has one). ``typical``
and ``harsh`` draw every difference uniformly within the tolerances below, on top of the scene's
``[world]``; the draw is a function of the scene, the reality and the seed only. Where each tolerance
comes from: docs/reality.md.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from enum import StrEnum

import mujoco
import numpy as np

from ftc_hw.model.arm import SURFACE_GROUP
from ftc_hw.model.build import arm_bodies, moves
from ftc_hw.model.true_arm import true_arm_spec, world_vendor_shell
from ftc_hw.scene import Scene
from ftc_hw.scene.vendor import VENDOR_SHELLS, shell_fetched
from ftc_hw.scene.world_spec import InertialError, WorldSpec


class Reality(StrEnum):
    IDEAL = "ideal"
    TYPICAL = "typical"
    HARSH = "harsh"


@dataclass(frozen=True)
class Tolerances:
    """Half-widths of the uniform draws (a relative one is a fraction of the modelled value)."""

    mass_rel: float  # each moving body's mass
    com_m: float  # each axis of each moving body's centre of mass
    inertia_rel: float  # each moving body's rotational inertia
    friction_rel: float  # each joint's Coulomb and viscous friction (scale 1 +- this)
    stribeck_rel: float  # each joint's breakaway excess, 0 .. this x its Coulomb friction
    torque_constant_rel: float  # each motor's torque constant
    mount_m: float  # each axis of the sensor's mount position
    mount_rad: float  # each axis of the sensor's mount rotation (rotation vector)
    gain_rel: float  # each axis' gain error
    crosstalk_rel: float  # each off-diagonal term (i, j), in units of range_i / range_j
    coloured_rel: float  # coloured noise std, 0 .. this x the white noise std
    coloured_tau_s: float  # its correlation time
    temperature_rise_K: float  # the sensor warms by 0 .. this during the run
    thermal_rel_per_K: float  # thermal drift per K, +- this x the white noise std
    shell_m: float  # each touchable geom's true surface lies 0.5 .. 1 x this outside its primitive
    vendor_shift_m: float  # each axis of each body's true shell off the vendor's meshes, where it has them
    # joint sensing (JOINT_DIFFERENCES; docs/reality.md): uniform between the two bounds of a pair
    ripple_rel: float  # each motor's torque ripple amplitude, 0 .. this (a fraction of the torque)
    cogging_rel: float  # each motor's cogging amplitude at the joint, 0 .. this x its Coulomb friction
    torque_constant_per_K: tuple[float, float]  # the torque constants' relative change per K (the magnets')
    friction_per_K: tuple[float, float]  # joint friction's relative change per K (the gears' grease)
    winding_start_K: float  # each winding starts +- this (K) off the temperature the model's values hold at
    winding_heating_K_per_A2: float  # the windings' steady rise per A^2 (not drawn: the reality's value)
    winding_tau_s: float  # their thermal time constant (not drawn)
    torque_offset_rel: float  # each joint torque sensor's offset, +- this x its range
    torque_drift_rel_per_K: float  # its drift per K of winding temperature, +- this x its range


TOLERANCES: dict[Reality, Tolerances] = {
    Reality.TYPICAL: Tolerances(mass_rel=0.03, com_m=0.003, inertia_rel=0.10, friction_rel=0.30, stribeck_rel=0.3,
                                torque_constant_rel=0.05, mount_m=0.001, mount_rad=math.radians(0.3),
                                gain_rel=0.01, crosstalk_rel=0.005, coloured_rel=0.5, coloured_tau_s=1.0,
                                temperature_rise_K=3.0, thermal_rel_per_K=0.3, shell_m=0.003,
                                vendor_shift_m=0.001, ripple_rel=0.02, cogging_rel=0.1,
                                torque_constant_per_K=(-0.0012, -0.0009), friction_per_K=(-0.015, -0.005),
                                winding_start_K=5.0, winding_heating_K_per_A2=0.5, winding_tau_s=900.0,
                                torque_offset_rel=0.002, torque_drift_rel_per_K=2e-4),
    Reality.HARSH: Tolerances(mass_rel=0.08, com_m=0.008, inertia_rel=0.25, friction_rel=0.60, stribeck_rel=0.6,
                              torque_constant_rel=0.10, mount_m=0.003, mount_rad=math.radians(1.0),
                              gain_rel=0.025, crosstalk_rel=0.015, coloured_rel=1.0, coloured_tau_s=3.0,
                              temperature_rise_K=8.0, thermal_rel_per_K=0.6, shell_m=0.005,
                              vendor_shift_m=0.002, ripple_rel=0.05, cogging_rel=0.25,
                              torque_constant_per_K=(-0.0012, -0.0009), friction_per_K=(-0.025, -0.01),
                              winding_start_K=15.0, winding_heating_K_per_A2=1.0, winding_tau_s=600.0,
                              torque_offset_rel=0.005, torque_drift_rel_per_K=5e-4),
}

DIFFERENCES = ("inertials", "friction", "torque_constant", "mount", "gain", "coloured_noise", "thermal", "shell")
# what only the joint signals see (currents, joint torques): drawn with the rest, not columns of
# `ftc bench reality` (its F/T pipeline reads none of them)
JOINT_DIFFERENCES = ("motor_ripple", "joint_thermal", "torque_sensor_offsets")
ALL_DIFFERENCES = DIFFERENCES + JOINT_DIFFERENCES


def with_reality(scene: Scene, reality: Reality | str, seed: int = 0,
                 only: tuple[str, ...] | None = None) -> Scene:
    """The scene whose ``world`` is a draw of ``reality`` (seeded) on top of its own ``[world]``.
    ``only``: draw just these of :data:`ALL_DIFFERENCES` (the rest stay as the scene has them)."""
    reality = Reality(reality)
    if reality is Reality.IDEAL:
        return scene
    tol = TOLERANCES[reality]
    rng = np.random.default_rng([seed, 21_000 + list(Reality).index(reality)])
    arm = _moving_bodies_and_shells(scene)  # the true arm compiled once for the draw and the shell
    drawn = _draw(scene, tol, rng, arm)  # every difference drawn, so a subset keeps the same values
    base = scene.world
    keep = set(ALL_DIFFERENCES) if only is None else set(only)
    unknown = keep - set(ALL_DIFFERENCES)
    if unknown:
        raise ValueError(f"unknown differences {sorted(unknown)} (known: {', '.join(ALL_DIFFERENCES)})")
    changes: dict = {}
    for name in keep:
        changes.update(_compose(name, base, drawn))
    if "shell" in keep:
        changes.update(_vendor_shell(scene, changes["shell_offsets"], arm[1], drawn.vendor_shell_shift))
    return dataclasses.replace(scene, world=dataclasses.replace(base, **changes))


def _vendor_shell(scene: Scene, offsets: dict[str, float], bodies_of: dict[str, str],
                  shifts: dict[str, np.ndarray]) -> dict:
    """The scene's vendor meshes as the shell, where fetched (``ftc scenes meshes``), each body's shifted
    by its drawn amount: no drawn offset on the primitives of the bodies they cover. Not fetched: the
    drawn offsets stay (``shell_source`` says which)."""
    name = scene.robot.vendor_shell
    if name is None or scene.world.vendor_shell is not None or not shell_fetched(name):
        return {}
    covered = set(VENDOR_SHELLS[name].bodies)
    return {"vendor_shell": name, "shell_offsets": {g: v for g, v in offsets.items() if bodies_of[g] not in covered},
            "vendor_shell_shift": {b: shifts[b] for b in covered if b in shifts}}


def shell_source(scene: Scene) -> str:
    """What a world's touched surface is: the vendor's meshes, primitives with offsets, or the model."""
    w = scene.world
    vendor = world_vendor_shell(scene)
    if vendor is not None:
        return f"{vendor} meshes" + (" (shifted)" if any(np.any(v) for v in w.vendor_shell_shift.values()) else "")
    if w.shell_offset or any(w.shell_offsets.values()):
        missing = scene.robot.vendor_shell is not None and not shell_fetched(scene.robot.vendor_shell)
        return "primitives + offset" + (" (vendor meshes not fetched: ftc scenes meshes)" if missing else "")
    return "the model's primitives"


def _draw(scene: Scene, tol: Tolerances, rng: np.random.Generator,
          arm: tuple[list[str], dict[str, str]]) -> WorldSpec:
    r, s, w = scene.robot, scene.sensor, scene.world
    n = scene.n_joints
    coulomb = r.friction_coulomb if w.friction_coulomb is None else w.friction_coulomb
    viscous = r.friction_viscous if w.friction_viscous is None else w.friction_viscous
    stribeck = np.zeros(n) if w.friction_stribeck is None else w.friction_stribeck
    kt = r.torque_constant if w.torque_constant is None else w.torque_constant
    bodies, geoms = arm
    inertials = {b: InertialError(1.0 + rng.uniform(-tol.mass_rel, tol.mass_rel),
                                  rng.uniform(-tol.com_m, tol.com_m, 3),
                                  1.0 + rng.uniform(-tol.inertia_rel, tol.inertia_rel)) for b in bodies}
    gain = np.diag(1.0 + rng.uniform(-tol.gain_rel, tol.gain_rel, 6))
    # crosstalk is specified in per cent of full scale: term (i, j) in units of range_i / range_j
    full = np.ones(6) if s is None else np.asarray(s.range, dtype=float)  # no F/T sensor: drawn, not used
    cross = rng.uniform(-tol.crosstalk_rel, tol.crosstalk_rel, (6, 6)) * full[:, None] / full[None, :]
    np.fill_diagonal(cross, 0.0)
    white = np.zeros(6) if s is None else np.sqrt(np.diag(s.noise_cov))
    drawn = WorldSpec(
        inertials=inertials,
        friction_coulomb=coulomb * (1.0 + rng.uniform(-tol.friction_rel, tol.friction_rel, n)),
        friction_viscous=viscous * (1.0 + rng.uniform(-tol.friction_rel, tol.friction_rel, n)),
        friction_stribeck=stribeck + coulomb * rng.uniform(0.0, tol.stribeck_rel, n),
        torque_constant=kt * (1.0 + rng.uniform(-tol.torque_constant_rel, tol.torque_constant_rel, n)),
        sensor_offset=rng.uniform(-tol.mount_m, tol.mount_m, 3),
        sensor_rotation=rng.uniform(-tol.mount_rad, tol.mount_rad, 3),
        sensor_gain=gain @ (np.eye(6) + cross),
        coloured_noise_std=white * rng.uniform(0.0, tol.coloured_rel),
        coloured_noise_tau_s=tol.coloured_tau_s,
        temperature_drift=white * rng.uniform(-tol.thermal_rel_per_K, tol.thermal_rel_per_K, 6),
        temperature_rise_K=float(rng.uniform(0.0, tol.temperature_rise_K)),
        shell_offsets={g: float(rng.uniform(0.5, 1.0) * tol.shell_m) for g in geoms},
    )
    # drawn last, so the draws above are what they were before this difference existed
    shifts = {b: rng.uniform(-tol.vendor_shift_m, tol.vendor_shift_m, 3) for b in _shell_bodies(scene)}
    return dataclasses.replace(drawn, vendor_shell_shift=shifts, **_draw_joint_sensing(scene, tol, rng, coulomb))


def _draw_joint_sensing(scene: Scene, tol: Tolerances, rng: np.random.Generator, coulomb: np.ndarray) -> dict:
    """The joint sensing's differences (drawn after all the others, which so keep their values)."""
    n = scene.n_joints
    out = {"current_ripple": rng.uniform(0.0, tol.ripple_rel, n),
           "cogging_torque": coulomb * rng.uniform(0.0, tol.cogging_rel, n),
           "motor_angle_offset": rng.uniform(0.0, 2 * math.pi, n),
           "torque_constant_per_K": float(rng.uniform(*tol.torque_constant_per_K)),
           "friction_per_K": float(rng.uniform(*tol.friction_per_K)),
           "winding_start_K": rng.uniform(-tol.winding_start_K, tol.winding_start_K, n),
           "winding_heating_K_per_A2": tol.winding_heating_K_per_A2, "winding_tau_s": tol.winding_tau_s}
    jt = scene.joint_torque
    full = np.ones(n) if jt is None else np.asarray(jt.range, dtype=float)  # drawn alike with or without sensors
    out["joint_torque_offset"] = full * rng.uniform(-tol.torque_offset_rel, tol.torque_offset_rel, n)
    out["joint_torque_drift_per_K"] = full * rng.uniform(-tol.torque_drift_rel_per_K, tol.torque_drift_rel_per_K, n)
    return out


def _shell_bodies(scene: Scene) -> list[str]:
    """The bodies the scene's vendor meshes cover (none without vendor meshes)."""
    name = scene.robot.vendor_shell
    return [] if name is None else list(VENDOR_SHELLS[name].bodies)


def _compose(name: str, base: WorldSpec, d: WorldSpec) -> dict:
    """The fields of difference ``name``: the draw on top of the scene's own ``[world]`` values."""
    if name == "inertials":
        merged = dict(base.inertials)
        for b, e in d.inertials.items():
            o = merged.get(b, InertialError())
            merged[b] = InertialError(o.mass_scale * e.mass_scale, o.com_offset + e.com_offset,
                                      o.inertia_scale * e.inertia_scale)
        return {"inertials": merged}
    if name == "friction":  # drawn about the scene's own true values already (_draw)
        return {"friction_coulomb": d.friction_coulomb, "friction_viscous": d.friction_viscous,
                "friction_stribeck": d.friction_stribeck}
    if name == "torque_constant":
        return {"torque_constant": d.torque_constant}
    if name == "mount":
        return {"sensor_offset": base.sensor_offset + d.sensor_offset,
                "sensor_rotation": base.sensor_rotation + d.sensor_rotation}
    if name == "gain":
        return {"sensor_gain": d.sensor_gain @ base.sensor_gain}
    if name == "coloured_noise":
        return {"coloured_noise_std": np.maximum(base.coloured_noise_std, d.coloured_noise_std),
                "coloured_noise_tau_s": d.coloured_noise_tau_s}
    if name == "thermal":
        return {"temperature_drift": base.temperature_drift + d.temperature_drift,
                "temperature_rise_K": max(base.temperature_rise_K, d.temperature_rise_K)}
    if name == "motor_ripple":
        phase = d.motor_angle_offset if base.motor_angle_offset is None else base.motor_angle_offset
        return {"current_ripple": d.current_ripple, "cogging_torque": d.cogging_torque, "motor_angle_offset": phase}
    if name == "joint_thermal":
        start = d.winding_start_K if base.winding_start_K is None else base.winding_start_K + d.winding_start_K
        return {"torque_constant_per_K": base.torque_constant_per_K or d.torque_constant_per_K,
                "friction_per_K": base.friction_per_K or d.friction_per_K, "winding_start_K": start,
                "winding_heating_K_per_A2": base.winding_heating_K_per_A2 or d.winding_heating_K_per_A2,
                "winding_tau_s": d.winding_tau_s if base.winding_heating_K_per_A2 == 0.0 else base.winding_tau_s}
    if name == "torque_sensor_offsets":
        offset = d.joint_torque_offset if base.joint_torque_offset is None else (
            base.joint_torque_offset + d.joint_torque_offset)
        drift = d.joint_torque_drift_per_K if base.joint_torque_drift_per_K is None else (
            base.joint_torque_drift_per_K + d.joint_torque_drift_per_K)
        return {"joint_torque_offset": offset, "joint_torque_drift_per_K": drift}
    return {"shell_offsets": {g: base.shell_of(g) + v for g, v in d.shell_offsets.items()}}


def _moving_bodies_and_shells(scene: Scene) -> tuple[list[str], dict[str, str]]:
    """The arm's bodies (a base sensor's: those it carries) that a joint moves, and the touchable
    primitive geoms of the arm's bodies (geom -> body)."""
    m = true_arm_spec(scene, shell="none").compile()  # the primitives, as the draw has always seen them
    arm = arm_bodies(m, scene)
    bodies = [m.body(b).name for b in arm if moves(m, b)]
    geoms = {m.geom(g).name: m.body(int(m.geom_bodyid[g])).name for g in range(m.ngeom)
             if m.geom_group[g] == SURFACE_GROUP and int(m.geom_bodyid[g]) in arm
             and m.geom_type[g] != mujoco.mjtGeom.mjGEOM_MESH and m.geom(g).name}
    return bodies, geoms
