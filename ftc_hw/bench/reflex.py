"""``ftc bench reflex``: the stop reflex across the process boundary, ``stops`` onsets per arm.

Each arm's device (ur5e's UR over RTDE + dashboard, dxl-arm's DYNAMIXEL bus) is emulated in its world
and read by a reader process of its own (:class:`~ftc_hw.app.serving.serve.ServedReaders`, as ``ftc monitor``
and ``ftc serve`` run it); this process stands where the monitor stands. Per stop, an onset event is
made (its ``t_host_ns`` now: the onset sample's time, as if the detector had judged it at once) and
sent as the monitor's :class:`~ftc_hw.app.monitor.reflex.StopReflex` sends it (``RemoteRig.stop_arm``: Zenoh,
express); the arm's reader stops the arm and says when on the bus (a ``stopped`` event, one host's
monotonic clock):

- ``received``: onset to the command in the reader, the moment it calls ``stop()``, whose first act is
  writing the stop (dashboard ``stop``; Goal Position := Present Position): the stop sent;
- ``returned``: onset to ``stop()`` returned (UR: the dashboard's reply included).

Beside it, the same onsets through the same ``StopReflex`` with the adapter in this process
(``--readers thread``): what the boundary costs. The detector's own latency (the onset sample's
arrival to its judgement) is the pipeline's, the same either way: ``ftc bench compensation``.
"""
from __future__ import annotations

import json
import os
import random
import time
from pathlib import Path
from typing import Any

import numpy as np
from rich.table import Table

from ftc_hw.app.monitor.reflex import StopReflex
from ftc_hw.app.serving.remote_rig import RemoteRig
from ftc_hw.app.serving.serve import ServedReaders
from ftc_hw.app.setup.rig import build_rig
from ftc_hw.bench.report import table_console
from ftc_hw.bus import EVENTS_CONTACT, EVENTS_DEVICE, Bus, ContactEvent, joints_topic
from ftc_hw.bus.remote import free_loopback_endpoint
from ftc_hw.devices.base import responsive_readers
from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.host import WorldHost

ARMS = (("ur5e", "ur-rtde", "127.0.0.62"), ("dxl-arm", "dynamixel", None))
MEDIAN_MS, P99_MS = 1.0, 2.0  # issue 22's acceptance


def _onset(contact_id: int) -> ContactEvent:
    return ContactEvent.make(time.monotonic_ns(), "onset", "bench", np.zeros(3), np.zeros(3), contact_id=contact_id)


def _pace(rng: random.Random) -> None:
    time.sleep(rng.uniform(0.02, 0.06))  # stops at random phases of the devices' cycles


def _play(bus: Bus, reflex: StopReflex, stops: int, seed: int) -> None:
    """``stops`` onsets on ``bus`` (the monitor's), paced, each waited for (or 1 s)."""
    rng = random.Random(seed)
    for i in range(1, stops + 1):
        _pace(rng)
        bus.publish(EVENTS_CONTACT, _onset(i))
        end = time.monotonic() + 1.0
        while len(reflex.stops) + len(reflex.errors) < i and time.monotonic() < end:
            time.sleep(0.0005)


def across_processes(scene: Any, device: Any, world: WorldHost, stops: int, seed: int) -> dict[str, Any]:
    """``stops`` onsets through ``StopReflex`` to the arm's reader process; its ``stopped`` events."""
    listen = free_loopback_endpoint()
    bus = Bus(history=4 * stops)
    readers = ServedReaders(scene, [device], "bench-reflex", [listen], endpoints=world.endpoints)
    rig = RemoteRig(bus, listen, "bench-reflex", [joints_topic(device.name)], timeout=20.0, readers=readers)
    try:
        rig.open().wait()
        time.sleep(0.5)
        reflex = StopReflex(bus, rig.stop_arm, inline=True)  # as the monitor does
        try:
            _play(bus, reflex, stops, seed)
            time.sleep(0.5)  # the last stopped event on its way
        finally:
            reflex.close()
        said = {int(e.counters["contact_id"]): e.counters for e in bus.history(EVENTS_DEVICE) if e.kind == "stopped"}
    finally:
        rig.close()
    return _latencies([said[i] for i in sorted(said)], stops, reflex.errors)


def in_process(scene: Any, device: Any, world: WorldHost, stops: int, seed: int) -> dict[str, Any]:
    """The same onsets through ``StopReflex`` to the adapter in this process (``--readers thread``)."""
    rig = build_rig(scene, devices=[device], endpoints=world.endpoints, timeout=20.0)
    with rig:
        time.sleep(0.5)
        reflex = StopReflex(rig.bus, lambda _ev: rig.arm.stop())
        try:
            _play(rig.bus, reflex, stops, seed)
        finally:
            reflex.close()
    return _latencies(reflex.stops, stops, reflex.errors)


def _latencies(stopped: list[Any], stops: int, errors: list[str]) -> dict[str, Any]:
    """From each stop's ``sent_after_onset_ms`` and ``stop_call_ms``: onset to stop sent, to stop() returned."""
    return {"received_ms": [s["sent_after_onset_ms"] for s in stopped],
            "returned_ms": [s["sent_after_onset_ms"] + s["stop_call_ms"] for s in stopped],
            "missing": stops - len(stopped), "errors": errors}


def bench_arm(scene_name: str, kind: str, address: str | None, stops: int, seed: int) -> dict[str, Any]:
    scene = load_scene(scene_name)
    device = next(d for d in scene.devices if d.kind == kind)
    options = {device.name: {"address": address}} if address else None
    with WorldHost(scene, "hold", devices=[device.name], options=options, noise=False) as world:
        return {"processes": across_processes(scene, device, world, stops, seed),
                "in_process": in_process(scene, device, world, stops, seed)}


def _stats(values: list[float]) -> dict[str, float]:
    if not values:
        return {"n": 0}
    v = np.asarray(values)
    return {"n": len(v), "median": float(np.median(v)), "p99": float(np.percentile(v, 99)), "max": float(v.max())}


def run(json_path: str | Path | None = None, stops: int = 200, seed: int = 0) -> dict[str, Any]:
    console = table_console()
    load = os.getloadavg()
    console.print(f"[bold]stop reflex[/bold]: {stops} onsets per arm; load average {load[0]:.2f} {load[1]:.2f} "
                  f"{load[2]:.2f} on {os.cpu_count()} CPUs")
    table = Table(title="ftc bench reflex: onset to stop (ms; one host's monotonic clock)")
    for col in ("arm", "readers", "to", "n", "median", "p99", "max", "missing", f"<= {MEDIAN_MS:g} / {P99_MS:g}"):
        table.add_column(col)
    result: dict[str, Any] = {"stops": stops, "load_average": load, "arms": {}}
    with responsive_readers():  # as the monitor runs
        for scene_name, kind, address in ARMS:
            res = bench_arm(scene_name, kind, address, stops, seed)
            result["arms"][scene_name] = res
            for mode, label in (("processes", "own process"), ("in_process", "in this process")):
                for part in ("received", "returned"):
                    s = _stats(res[mode][f"{part}_ms"])
                    res[mode][part] = s
                    ok = s["n"] > 0 and s["median"] <= MEDIAN_MS and s["p99"] <= P99_MS
                    table.add_row(scene_name, label, "stop sent" if part == "received" else "stop() returned",
                                  str(s["n"]), *(f"{s.get(k, float('nan')):.3f}" for k in ("median", "p99", "max")),
                                  str(res[mode]["missing"]),
                                  ("[green]yes[/]" if ok else "[red]no[/]") if part == "received" else "")
    console.print(table)
    load_end = os.getloadavg()
    result["load_average_end"] = load_end
    console.print(f"load average at the end {load_end[0]:.2f} {load_end[1]:.2f} {load_end[2]:.2f}")
    if json_path is not None:
        Path(json_path).write_text(json.dumps(result, indent=2, default=float))
    return result
