"""UR recordings as users have them, written from the simulated world (no emulator: the tests that use
them compute): what a UR controller streams at 500 Hz (``timestamp``, ``actual_q``, ``actual_qd``,
``actual_current``, ``ft_raw_wrench``), written in UR's RTDE client format or ur_rtde's, optionally
thinned to about 100 Hz with jittered steps (8-34 ms, as real logs are) and with bad rows put in (a
value of 1e300, a NaN, a row cut short, a repeated timestamp). The world's truth comes back beside it.
tests/record/ur_recording.py records the same formats from the emulated arm through ur_rtde."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ftc_hw.model import ArmModel
from ftc_hw.record.ur_csv import UR_CLIENT, write_ur_csv
from ftc_hw.scene import Scene
from ftc_hw.sim_devices.world import World, build_scenario

RATE_HZ = 500.0


@dataclass
class WorldRun:
    columns: dict[str, np.ndarray]  # the controller's stream at 500 Hz, by RTDE name
    contact: np.ndarray  # (N,) bool: a contact at that sample (truth)
    link: list  # the strongest contact's link, or None
    force: np.ndarray  # (N,) N: its force's magnitude


def run_world(scene: Scene, world_scene: Scene, scenario: str, seconds: float, seed: int) -> WorldRun:
    """``scenario`` built on ``scene``'s model, run in a world of ``world_scene`` (a drawn reality)."""
    setup = build_scenario(scenario, scene, ArmModel(scene), seed, seconds)
    world = World(world_scene, setup, seed=seed)
    every = round(1.0 / (RATE_HZ * world.dt))
    rows: dict[str, list] = {k: [] for k in ("timestamp", "actual_q", "actual_qd", "actual_current", "ft_raw_wrench",
                                             "joint_torques")}
    contact, link, force = [], [], []
    for _ in range(int(round(seconds / world.dt))):
        s = world.step()
        if world.steps % every:
            continue
        rows["timestamp"].append(1000.0 + s.t)  # the controller's clock: seconds since it started
        rows["actual_q"].append(s.q)
        rows["actual_qd"].append(s.qd)
        rows["actual_current"].append(world.read_current(s))
        rows["ft_raw_wrench"].append(world.read_sensor(s).wrench if s.wrench is not None else np.zeros(6))
        rows["joint_torques"].append(world.read_joint_torques(s))  # a Franka's tau_J (tests/app/ros: bags)
        main = max(s.contacts, key=lambda c: float(np.linalg.norm(c.force)), default=None)
        contact.append(main is not None)
        link.append(main.link if main is not None else None)
        force.append(float(np.linalg.norm(main.force)) if main is not None else 0.0)
    columns = {k: np.array(v) for k, v in rows.items()}
    if world_scene.sensor is not None and world_scene.sensor.mount == "base":  # a Net F/T under the base
        columns["base_ft_wrench"] = columns.pop("ft_raw_wrench")  # (tests/app/ros: bags)
    elif world_scene.sensor is None:
        del columns["ft_raw_wrench"]
    if world_scene.joint_torque is None:
        del columns["joint_torques"]
    return WorldRun(columns, np.array(contact), link, np.array(force))


def thinned(columns: dict[str, np.ndarray], rng: np.random.Generator) -> dict[str, np.ndarray]:
    """About 100 Hz with jitter: each kept row 8 to 12 ms after the previous one, one in six 14 to 34 ms."""
    n = len(columns["timestamp"])
    steps = np.where(rng.random(n // 4) < 5 / 6, rng.integers(4, 7, size=n // 4), rng.integers(7, 18, size=n // 4))
    keep = np.cumsum(steps)
    keep = keep[keep < n]
    return {k: v[keep] for k, v in columns.items()}


def write_with_bad_rows(path: Path, columns: dict[str, np.ndarray], *, style: str = UR_CLIENT) -> dict[str, int]:
    """The file, with four bad rows put in at fixed places: which kind where (what the reader must skip)."""
    cols = {k: v.astype(float).copy() for k, v in columns.items()}
    n = len(cols["timestamp"])
    cols["actual_q"][n // 5, 2] = 1e300  # a corrupted value, as real logs have
    cols["actual_current" if "actual_current" in cols else "actual_qd"][2 * n // 5, 0] = np.nan
    cols["timestamp"][3 * n // 5] = cols["timestamp"][3 * n // 5 - 1]  # a repeated timestamp
    write_ur_csv(path, cols, style=style)
    lines = path.read_text().splitlines(keepends=True)
    cut = 1 + 4 * n // 5  # + the header line
    lines[cut] = lines[cut][: len(lines[cut]) // 2] + "\n"  # a row cut short
    path.write_text("".join(lines))
    return {"out_of_range": 1, "not_finite": 1, "time_repeated": 1, "cut_short": 1}
