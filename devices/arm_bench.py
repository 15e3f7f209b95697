"""``ftc bench arms``: the arm adapters' acceptance numbers, measured against the emulators.

Each part runs the scene's world and its arm emulator in their own processes
(:class:`sim_devices.world_process.WorldProcess`, the code ``ftc sim`` runs) and the client here:

* UR: ``rtde_receive.RTDEReceiveInterface(address)`` with default arguments for ``duration`` s --
  every new packet's ``actual_q`` compared with the world's joint sample of the same time (the
  world's shared-memory ring), packet rate over the wall clock, packets missed by the poller;
* Dynamixel: dynamixel_sdk GroupSyncRead (and Fast Sync Read) of 126..135 from all 4 servos, reads/s;
* both adapters: JointFrame rate on the bus, ``stop()`` latency (call to the world applying the
  halt, both on CLOCK_MONOTONIC) against one control period, and, after SIGKILL of the emulator, the
  time to the ``stale`` event and, after the restarted emulator is ready, to ``connect``.
"""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from ftc_hw.bus import Bus
from ftc_hw.scene import load_scene
from sim_devices.world_process import WorldProcess

UR_ADDRESS = "127.0.0.61"


def _wait_event(sub: Any, kind: str, timeout: float) -> Any:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        for ev in sub.drain():
            if ev.kind == kind:
                return ev
        time.sleep(0.001)
    return None


def _stop_latencies(world: WorldProcess, adapter: Any, n: int, between: Any = None) -> list[float]:
    out = []
    for _ in range(n):
        if between is not None:
            between()
        time.sleep(0.1)
        before = len(world.applied())
        t0 = time.monotonic_ns()
        adapter.stop()
        time.sleep(0.05)
        halts = [a for a in world.applied()[before:] if a.kind in ("stop", "goal")]
        if halts:
            out.append((halts[0].t_host_ns - t0) / 1e6)
    return out


def _kill_restart(world: WorldProcess, adapter: Any, bus: Bus, name: str, n: int) -> dict[str, list[float]]:
    events = bus.subscribe("events/", maxsize=100_000)
    stale, reconnect = [], []
    for _ in range(n):
        time.sleep(0.3)
        events.drain()
        t_kill = time.monotonic_ns()
        world.kill(name)
        ev = _wait_event(events, "stale", 5.0)
        stale.append((ev.t_host_ns - t_kill) / 1e6 if ev else float("inf"))
        time.sleep(0.3)  # the emulator stays dead a while: the adapter is in its backoff
        world.restart(name)
        t_ready = time.monotonic_ns()
        ev = _wait_event(events, "connect", 10.0)
        reconnect.append((ev.t_host_ns - t_ready) / 1e6 if ev else float("inf"))
    events.close()
    return {"stale_ms": stale, "reconnect_ms": reconnect}


def _adapter_rate(bus: Bus, topic: str, seconds: float) -> dict[str, float]:
    sub = bus.subscribe(topic, maxsize=1_000_000)
    t0 = time.monotonic()
    time.sleep(seconds)
    frames = sub.drain()
    wall = time.monotonic() - t0
    sub.close()
    gaps = sum(1 for f in frames if f.flags & 4)
    return {"frames": len(frames), "rate_hz": len(frames) / wall, "seq_gap_frames": gaps}


# -- UR -------------------------------------------------------------------------------------------------
def bench_ur(duration: float) -> dict[str, Any]:
    import rtde_receive

    from .arm_registry import make_arm_adapter

    scene = load_scene("ur5e")
    device = next(d for d in scene.devices if d.kind == "ur-rtde")
    out: dict[str, Any] = {}
    with WorldProcess(scene, "sweep", devices=[device.name], options={device.name: {"address": UR_ADDRESS}}) as w:
        ring = w.joint_reader()
        world_q: dict[float, np.ndarray] = {}
        r = rtde_receive.RTDEReceiveInterface(UR_ADDRESS)  # default arguments
        ts, qs = [], []
        last = None
        t0 = time.monotonic()
        next_drain = t0
        while (now := time.monotonic()) < t0 + duration:
            t = r.getTimestamp()
            if t != last:
                q = r.getActualQ()
                if r.getTimestamp() == t:
                    ts.append(t)
                    qs.append(q)
                last = t
            if now >= next_drain:  # the ring holds ~2 s of world samples
                next_drain = now + 0.1
                for rec in ring.new():
                    world_q[float(rec[0])] = rec[1:7]
            time.sleep(0.00005)
        wall = time.monotonic() - t0
        connected = r.isConnected()
        r.disconnect()
        for rec in ring.new():
            world_q[float(rec[0])] = rec[1:7]
        errs = [float(np.max(np.abs(np.asarray(q) - world_q[t]))) for t, q in zip(ts, qs, strict=True) if t in world_q]
        ticks = round((ts[-1] - ts[0]) / 0.002) + 1 if ts else 0
        out["receive"] = {"duration_s": wall, "stream_rate_hz": ticks / wall, "packets_read": len(ts),
                          "read_rate_hz": len(ts) / wall, "missed_by_poller": ticks - len(ts),
                          "matched": len(errs), "max_abs_error_rad": max(errs) if errs else float("nan"),
                          "connected": connected}

        bus = Bus()
        adapter = make_arm_adapter(device, bus, w.endpoint(device.name), scene=scene)
        with adapter:
            adapter.wait_connected(5.0)
            time.sleep(0.5)
            out["adapter"] = _adapter_rate(bus, adapter.topic, min(10.0, duration))
            out["adapter"]["missed_packets"] = adapter.counters["missed_packets"]
            lat = _stop_latencies(w, adapter, 20, between=lambda: adapter.dashboard.command("play"))
            out["stop_ms"] = lat
            out["kill"] = _kill_restart(w, adapter, bus, device.name, 3)
    out["control_period_ms"] = 2.0
    return out


# -- Dynamixel ------------------------------------------------------------------------------------------
def bench_dxl(duration: float) -> dict[str, Any]:
    import dynamixel_sdk as sdk

    from .arm_registry import make_arm_adapter

    scene = load_scene("dxl-arm")
    device = next(d for d in scene.devices if d.kind == "dynamixel")
    ids = list(device.params["ids"])
    out: dict[str, Any] = {}
    seconds = min(10.0, duration)
    with WorldProcess(scene, "sweep", devices=[device.name]) as w:
        port = sdk.PortHandler(w.endpoint(device.name)["endpoint"])
        port.openPort()
        port.setBaudRate(int(device.params["baudrate"]))
        ph = sdk.PacketHandler(2.0)
        group = sdk.GroupSyncRead(port, ph, 126, 10)
        for i in ids:
            group.addParam(i)
        for label, call in (("sync_read", group.txRxPacket), ("fast_sync_read", group.fastSyncRead)):
            n = fails = 0
            t0 = time.monotonic()
            while time.monotonic() - t0 < seconds:
                fails += call() != sdk.COMM_SUCCESS
                n += 1
            out[label] = {"reads": n, "failures": fails, "reads_per_s": n / (time.monotonic() - t0)}
        port.closePort()

        bus = Bus()
        adapter = make_arm_adapter(device, bus, w.endpoint(device.name), scene=scene)
        with adapter:
            adapter.wait_connected(5.0)
            time.sleep(0.5)
            out["adapter"] = _adapter_rate(bus, adapter.topic, seconds)
            out["adapter"]["read_failures"] = adapter.counters["read_failures"]
            out["stop_ms"] = _stop_latencies(w, adapter, 20)
            out["kill"] = _kill_restart(w, adapter, bus, device.name, 3)
        out["control_period_ms"] = adapter.period * 1000.0  # the adapter's cycle (500 Hz by default)
    return out


# -- report ---------------------------------------------------------------------------------------------------
def acceptance(ur: dict[str, Any], dxl: dict[str, Any]) -> list[tuple[str, str, bool]]:
    rc = ur["receive"]
    rows = [
        ("UR receive: |q - world q| <= 1e-9 rad", f"{rc['max_abs_error_rad']:.1e} rad over {rc['matched']} packets",
         rc["matched"] > 0 and rc["max_abs_error_rad"] <= 1e-9),
        ("UR receive: 500 Hz +- 1 %", f"stream {rc['stream_rate_hz']:.2f} Hz over {rc['duration_s']:.0f} s; "
         f"read by a Python poller {rc['read_rate_hz']:.2f} Hz ({rc['missed_by_poller']} missed)",
         abs(rc["stream_rate_hz"] - 500.0) <= 5.0),
        ("DXL group sync read >= 1000 reads/s", f"{dxl['sync_read']['reads_per_s']:.0f}/s "
         f"(fast sync read {dxl['fast_sync_read']['reads_per_s']:.0f}/s)", dxl["sync_read"]["reads_per_s"] >= 1000),
        ("DXL adapter JointFrames >= 200 Hz", f"{dxl['adapter']['rate_hz']:.0f} Hz", dxl["adapter"]["rate_hz"] >= 200),
        ("UR adapter JointFrames at the device rate", f"{ur['adapter']['rate_hz']:.1f} Hz "
         f"({ur['adapter']['missed_packets']} packets missed)", abs(ur["adapter"]["rate_hz"] - 500.0) <= 5.0),
    ]
    for label, res in (("UR", ur), ("DXL", dxl)):
        lat = res["stop_ms"]
        rows.append((f"{label} stop() halts within one control period ({res['control_period_ms']:g} ms)",
                     f"median {np.median(lat):.2f} ms, p95 {np.percentile(lat, 95):.2f} ms, "
                     f"max {np.max(lat):.2f} ms over {len(lat)}",
                     bool(lat) and max(lat) <= res["control_period_ms"]))
        k = res["kill"]
        rows.append((f"{label} killed: stale within 100 ms",
                     f"max {max(k['stale_ms']):.1f} ms over {len(k['stale_ms'])}", max(k["stale_ms"]) <= 100.0))
        rows.append((f"{label} restarted: reconnected within 1 s",
                     f"max {max(k['reconnect_ms']):.0f} ms over {len(k['reconnect_ms'])}",
                     max(k["reconnect_ms"]) <= 1000.0))
    return rows


def run(json_path: str | Path | None = None, duration: float = 60.0) -> dict[str, Any]:
    """Measure, print a table, optionally write JSON; returns the numbers and the acceptance rows."""
    from rich.console import Console
    from rich.table import Table

    console = Console()
    console.print(f"[bold]arm adapters[/bold]: UR receive for {duration:g} s, then the rest (~1 min)")
    ur = bench_ur(duration)
    dxl = bench_dxl(duration)
    rows = acceptance(ur, dxl)
    table = Table(title="ftc bench arms")
    table.add_column("acceptance")
    table.add_column("measured")
    table.add_column("ok")
    for name, value, ok in rows:
        table.add_row(name, value, "[green]yes[/green]" if ok else "[red]NO[/red]")
    console.print(table)
    result = {"duration_s": duration, "ur": ur, "dynamixel": dxl,
              "acceptance": [{"name": n, "measured": v, "ok": bool(o)} for n, v, o in rows]}
    if json_path is not None:
        Path(json_path).write_text(json.dumps(result, indent=2, default=float))
    return result


if __name__ == "__main__":
    import sys

    run(sys.argv[1] if len(sys.argv) > 1 else None, float(sys.argv[2]) if len(sys.argv) > 2 else 60.0)
