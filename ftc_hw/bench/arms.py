"""``ftc bench arms``: the arm adapters' acceptance numbers, measured against the emulators.

Each part runs the scene's world and its arm emulator in their own processes
(:class:`ftc_hw.sim_devices.host.WorldHost`, as ``ftc sim`` runs it) and the client here:

* UR: ``rtde_receive.RTDEReceiveInterface(address)`` with default arguments for ``duration`` s --
  every new packet's ``actual_q`` compared with the world's joint sample of the same time (the
  world's shared-memory ring), packet rate over the wall clock, packets missed by the poller;
* Dynamixel: dynamixel_sdk GroupSyncRead (and Fast Sync Read) of 126..135 from all 5 servos, reads/s,
  beside the bus limit computed from the packets' sizes (instruction and status packets, 10 bits a
  byte at the baud rate, plus the servos' Return Delay Time), at the scene's 1 Mbit/s and at 57 600
  baud with the emulator's bus time on (its default), and once at 1 Mbit/s with bus time off
  (``bus_time = false``: a speed test of the emulator and the client, no bus limit);
* both adapters: JointFrame rate on the bus; ``stop()`` latency against one control period (the
  device's cycle, 2 ms for both), over ``stops`` calls: from the call until the arm's commanded motion
  is frozen -- the world applied the halt and its clock reached the first physics step using it (all
  times CLOCK_MONOTONIC, comparable across processes), with where the time went; after SIGKILL of the
  emulator, the time to the ``stale`` event and, after the restarted emulator is ready, to ``connect``.
"""
from __future__ import annotations

import json
import os
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import dynamixel_sdk as sdk
import numpy as np
import rtde_receive
from rich.table import Table

from ftc_hw.app.setup.rig import build_rig
from ftc_hw.bench.report import table_console
from ftc_hw.bus import Bus
from ftc_hw.devices.base import DeviceError, frozen_heap, responsive_readers
from ftc_hw.scene import load_scene
from ftc_hw.scene.overrides import apply_overrides
from ftc_hw.sim_devices.dxl_protocol import fast_status, packet, status
from ftc_hw.sim_devices.host import WorldHost
from ftc_hw.sim_devices.link import JointRecord

UR_ADDRESS = "127.0.0.61"


def _wait_event(sub: Any, kind: str, timeout: float) -> Any:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        for ev in sub.drain():
            if ev.kind == kind:
                return ev
        time.sleep(0.001)
    return None


def _stop_latencies(world: WorldHost, adapter: Any, n: int, between: Any = None, seed: int = 0) -> dict[str, Any]:
    """``n`` calls of ``adapter.stop()`` at random phases of the device's cycle (``between()`` before
    each, e.g. to set the arm moving). A stop's latency ends when the arm's commanded motion is frozen:
    the world has applied the halt (stop, or the Goal Position := Present Position write) *and* the
    world's clock has reached the physics step that first uses it -- the later of the host time at
    which the world applied it and that step's start on the real-time world clock. A stop the world
    never applied counts as infinite, and so does one that raised. Also: where the time went (call ->
    the device read the request -> the emulator handed the halt to the world -> the world applied it
    -> the step using it was due), the age of the Present Position a Dynamixel stop() held, and for
    goal halts how far the held goal was from the world's arm when the halt took effect."""
    rng = np.random.default_rng(seed)
    ring = world.joint_reader()
    n_q = world.scene.n_joints
    lat: list[float] = []
    parts: dict[str, list[float]] = defaultdict(list)
    held: list[float] = []
    held_lag: list[float] = []
    ages: list[float] = []
    failures: list[str] = []
    for _ in range(n):
        if between is not None:
            between()
        time.sleep(rng.uniform(0.04, 0.08))
        before = world.applied_count()
        t0 = time.monotonic_ns()
        try:
            adapter.stop()
        except DeviceError as exc:  # a stop that failed halted nothing
            failures.append(str(exc))
            lat.append(float("inf"))
            continue
        if getattr(adapter, "stop_position_age_s", None) is not None:
            ages.append(adapter.stop_position_age_s * 1e3)
        halt = None
        end = time.monotonic() + 1.0
        while halt is None and time.monotonic() < end:
            time.sleep(0.01)
            halt = next((a for a in world.applied(before) if a.kind in ("stop", "goal")), None)
        if halt is None:
            lat.append(float("inf"))
            continue
        effective = max(halt.t_host_ns, halt.t_due_ns)
        lat.append((effective - t0) / 1e6)
        if halt.t_rx_ns:
            parts["call -> device read the request (adapter, pty/TCP)"].append((halt.t_rx_ns - t0) / 1e6)
            parts["device read it -> halt handed to the world (emulator)"].append((halt.t_sent_ns - halt.t_rx_ns) / 1e6)
        parts["handed -> world applied it (command link, world)"].append((halt.t_host_ns - halt.t_sent_ns) / 1e6)
        parts["applied -> the step using it is due"].append((effective - halt.t_host_ns) / 1e6)
        if halt.kind == "goal":
            recs = ring.new()
            if recs:
                rec = min(recs, key=lambda r: abs(r[0] - halt.t_sim))
                joints = JointRecord.from_row(rec, n_q)
                gap, qd = np.asarray(halt.q) - joints.q, joints.qd
                held.append(float(np.max(np.abs(gap))))
                j = int(np.argmax(np.abs(qd)))
                if abs(qd[j]) > 0.05:  # moving: how long ago the arm was at the held position
                    held_lag.append(float(-gap[j] / qd[j]) * 1e3)
    out: dict[str, Any] = {"ms": lat, "parts_ms": dict(parts), "failures": failures}
    if held:
        out["held_goal_minus_q_rad"] = held
        out["held_goal_lag_ms"] = held_lag
    if ages:
        out["held_position_age_ms"] = ages
    return out


def _summary(values: list[float]) -> str:
    if not values:
        return "none"
    v = np.asarray(values, dtype=float)
    return (f"median {np.median(v):.2f} ms, p99 {np.percentile(v, 99):.2f} ms, max {np.max(v):.2f} ms "
            f"over {len(v)}")


def _kill_restart(world: WorldHost, adapter: Any, bus: Bus, name: str, n: int) -> dict[str, list[float]]:
    """``n`` times: SIGKILL the emulator, time to the ``stale`` event (0 when the adapter was already
    stale); 0.3 s later restart it, time from the restarted emulator being ready to ``connect``."""
    events = bus.subscribe("events/", maxsize=100_000)
    stale, reconnect = [], []
    for _ in range(n):
        time.sleep(0.3)
        events.drain()
        was_stale = adapter.stale
        t_kill = time.monotonic_ns()
        world.kill(name)
        ev = _wait_event(events, "stale", 5.0)
        stale.append(0.0 if was_stale and ev is None else (ev.t_host_ns - t_kill) / 1e6 if ev else float("inf"))
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
def bench_ur(duration: float, stops: int = 200, kills: int = 5) -> dict[str, Any]:
    scene = load_scene("ur5e")
    device = next(d for d in scene.devices if d.kind == "ur-rtde")
    out: dict[str, Any] = {}
    with WorldHost(scene, "sweep", devices=[device.name], options={device.name: {"address": UR_ADDRESS}},
                   noise=False) as w:
        ring = w.joint_reader()
        n_q = scene.n_joints  # a UR arm's 6
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
                    joints = JointRecord.from_row(rec, n_q)
                    world_q[joints.t] = joints.q
            time.sleep(0.00005)
        wall = time.monotonic() - t0
        connected = r.isConnected()
        r.disconnect()
        for rec in ring.new():
            joints = JointRecord.from_row(rec, n_q)
            world_q[joints.t] = joints.q
        errs = [float(np.max(np.abs(np.asarray(q) - world_q[t]))) for t, q in zip(ts, qs, strict=True) if t in world_q]
        ticks = round((ts[-1] - ts[0]) / 0.002) + 1 if ts else 0
        out["receive"] = {"duration_s": wall, "stream_rate_hz": ticks / wall, "packets_read": len(ts),
                          "read_rate_hz": len(ts) / wall, "missed_by_poller": ticks - len(ts),
                          "matched": len(errs), "max_abs_error_rad": max(errs) if errs else float("nan"),
                          "connected": connected}

        rig = build_rig(scene, devices=[device], endpoints=w.endpoints, timeout=5.0)
        bus, adapter = rig.bus, rig.arm
        with rig:
            time.sleep(0.5)
            out["adapter"] = _adapter_rate(bus, adapter.topic, min(10.0, duration))
            out["adapter"]["missed_packets"] = adapter.counters["missed_packets"]
            # play between stops: the emulator's world cannot resume its scenario, so the UR arm is at
            # rest; the halt is measured on the command path (dashboard -> controller -> world)
            out["stop"] = _stop_latencies(w, adapter, stops, between=lambda: adapter.dashboard.command("play"))
            out["kill"] = _kill_restart(w, adapter, bus, device.name, kills)
        out["control_period_ms"] = adapter.period * 1000.0  # the controller's cycle (500 Hz e-Series)
    return out


# -- Dynamixel ------------------------------------------------------------------------------------------
def _mover(world: WorldHost, adapter: Any, scene: Any) -> Any:
    """Before each stop: a Goal Position 0.15 rad away on every joint (alternating sides of home), once the
    world has it, so that stop() halts an arm in motion."""
    home = np.asarray(scene.robot.home, dtype=float)
    k = [0]

    def move() -> None:
        k[0] += 1
        before = world.applied_count()
        adapter.set_goal(home + (0.15 if k[0] % 2 else -0.15))
        end = time.monotonic() + 1.0
        while time.monotonic() < end and not any(a.kind == "goal" for a in world.applied(before)):
            time.sleep(0.002)

    return move


READ_ADDRESS, READ_LENGTH = 126, 10  # Present Current, Velocity, Position: what the adapter reads


def sync_read_limit(ids: list[int], baud: int, return_delay_us: float = 0.0, fast: bool = False) -> float:
    """Sync Reads a second a half-duplex bus at ``baud`` allows: one instruction packet and the status
    packets (one per servo, or one Fast Sync Read packet), 10 bits a byte (8N1), plus each answering
    servo's Return Delay Time (one for the fast packet, as the emulator spends it). Built from the packets
    themselves (all-zero data: no byte stuffing)."""
    params = READ_ADDRESS.to_bytes(2, "little") + READ_LENGTH.to_bytes(2, "little") + bytes(ids)
    instruction = packet(0xFE, 0x8A if fast else 0x82, params)
    data = bytes(READ_LENGTH)
    if fast:
        answers, delays = [fast_status([(0, i, data) for i in ids])], 1
    else:
        answers, delays = [status(i, 0, data) for i in ids], len(ids)
    n_bytes = len(instruction) + sum(len(a) for a in answers)
    return 1.0 / (n_bytes * 10.0 / baud + delays * return_delay_us * 1e-6)


def _sync_read_rates(endpoint: str, ids: list[int], baud: int, seconds: float) -> dict[str, Any]:
    """dynamixel_sdk's GroupSyncRead and Fast Sync Read as fast as they go for ``seconds`` each."""
    port = sdk.PortHandler(endpoint)
    port.openPort()
    port.setBaudRate(baud)
    ph = sdk.PacketHandler(2.0)
    group = sdk.GroupSyncRead(port, ph, READ_ADDRESS, READ_LENGTH)
    for i in ids:
        group.addParam(i)
    out = {}
    for label, call in (("sync_read", group.txRxPacket), ("fast_sync_read", group.fastSyncRead)):
        n = fails = 0
        t0 = time.monotonic()
        while time.monotonic() - t0 < seconds:
            fails += call() != sdk.COMM_SUCCESS
            n += 1
        out[label] = {"reads": n, "failures": fails, "reads_per_s": n / (time.monotonic() - t0)}
    port.closePort()
    return out


def bench_dxl_reads(seconds: float, bauds: tuple[int, ...] = (1_000_000, 57_600)) -> dict[str, Any]:
    """Sync Read rates against the emulator at each baud rate with bus time on, beside the bus limits,
    and at the first baud rate with bus time off (no limit: a speed test). The run with bus time off goes
    first: its cycle is this host's own turnaround (the client's code, the pty's wake-ups), which a
    bus-timed cycle adds to the bus's time; ``limit_with_host_per_s`` is the bus limit with it added."""
    scene = load_scene("dxl-arm")
    device = next(d for d in scene.devices if d.kind == "dynamixel")
    ids = list(device.params["ids"])
    delay_us = 2.0 * float(device.params.get("return_delay_time", 250))  # factory 250 x 2 us
    runs = [(bauds[0], False)] + [(b, True) for b in bauds]
    out: dict[str, Any] = {}
    host_s: dict[str, float] = {}
    for baud, bus_time in runs:
        changes: dict[str, Any] = {"baudrate": baud}
        if not bus_time:
            changes["bus_time"] = False
        run_scene = apply_overrides(scene, {device.name: changes}, "ftc bench arms")
        with WorldHost(run_scene, "sweep", devices=[device.name], noise=False) as w:
            rates = _sync_read_rates(w.endpoint(device.name)["endpoint"], ids, baud, seconds)
        for label, fast in (("sync_read", False), ("fast_sync_read", True)):
            r = rates[label]
            if not bus_time:
                host_s[label] = 1.0 / r["reads_per_s"]
                r["limit_per_s"] = r["limit_with_host_per_s"] = None
                continue
            r["limit_per_s"] = sync_read_limit(ids, baud, delay_us, fast)
            r["limit_with_host_per_s"] = 1.0 / (1.0 / r["limit_per_s"] + host_s[label])
        out[f"{baud}" + ("" if bus_time else "_no_bus_time")] = {"baud": baud, "bus_time": bus_time, **rates}
    return out


def bench_dxl(duration: float, stops: int = 200, kills: int = 5) -> dict[str, Any]:
    scene = load_scene("dxl-arm")
    device = next(d for d in scene.devices if d.kind == "dynamixel")
    seconds = min(10.0, duration)
    out: dict[str, Any] = {"reads": bench_dxl_reads(seconds)}
    with WorldHost(scene, "sweep", devices=[device.name], noise=False) as w:

        rig = build_rig(scene, devices=[device], endpoints=w.endpoints, timeout=5.0)
        bus, adapter = rig.bus, rig.arm
        with rig:
            time.sleep(0.5)
            out["adapter"] = _adapter_rate(bus, adapter.topic, seconds)
            out["adapter"]["read_failures"] = adapter.counters["read_failures"]
            out["stop"] = _stop_latencies(w, adapter, stops, between=_mover(w, adapter, scene))
            out["kill"] = _kill_restart(w, adapter, bus, device.name, kills)
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
        *_dxl_read_rows(dxl["reads"]),
        ("DXL adapter JointFrames >= 200 Hz", f"{dxl['adapter']['rate_hz']:.0f} Hz", dxl["adapter"]["rate_hz"] >= 200),
        ("UR adapter JointFrames at the device rate", f"{ur['adapter']['rate_hz']:.1f} Hz "
         f"({ur['adapter']['missed_packets']} packets missed)", abs(ur["adapter"]["rate_hz"] - 500.0) <= 5.0),
    ]
    for label, res in (("UR", ur), ("DXL", dxl)):
        lat, period = res["stop"]["ms"], res["control_period_ms"]
        over = sum(x > period for x in lat)
        rows.append((f"{label} stop() halts within one control period ({period:g} ms)",
                     f"{_summary(lat)}; {over} over {period:g} ms", bool(lat) and over == 0))
        k = res["kill"]
        rows.append((f"{label} killed: stale within 100 ms",
                     f"max {max(k['stale_ms']):.1f} ms over {len(k['stale_ms'])}", max(k["stale_ms"]) <= 100.0))
        rows.append((f"{label} restarted: reconnected within 1 s",
                     f"max {max(k['reconnect_ms']):.0f} ms over {len(k['reconnect_ms'])}",
                     max(k["reconnect_ms"]) <= 1000.0))
    return rows


def _dxl_read_rows(reads: dict[str, Any]) -> list[tuple[str, str, bool]]:
    """Where bus time is on, each rate between its two bounds, 10 % either side: at most the bus limit (the
    bus's time alone, from the packets), at least the bus limit with this host's own turnaround added (the
    cycle with bus time off: the client's code and the pty's wake-ups, and the emulator's work, which a
    bus-timed cycle partly hides behind the bus's time). A rate above the first means bus time is not spent;
    below the second, spent twice. With bus time off, a speed test (>= 1000/s)."""
    rows = []
    for run in reads.values():
        sr, fsr = run["sync_read"], run["fast_sync_read"]
        if run["bus_time"]:
            name = (f"DXL Sync Read at {run['baud']} baud between the bus limit with this host's turnaround "
                    "and the bus limit (10 % either side)")
            text = "; ".join(f"{label}{r['reads_per_s']:.0f}/s: bus limit {r['limit_per_s']:.0f}/s "
                             f"({r['reads_per_s'] / r['limit_per_s']:.0%}), with the host's turnaround "
                             f"{r['limit_with_host_per_s']:.0f}/s ({r['reads_per_s'] / r['limit_with_host_per_s']:.0%})"
                             for label, r in (("", sr), ("fast ", fsr)))
            ok = all(0.9 * r["limit_with_host_per_s"] <= r["reads_per_s"] <= 1.1 * r["limit_per_s"] for r in (sr, fsr))
        else:
            name = f"DXL Sync Read at {run['baud']} baud, bus time off (speed test) >= 1000/s"
            text = f"{sr['reads_per_s']:.0f}/s; fast {fsr['reads_per_s']:.0f}/s"
            ok = sr["reads_per_s"] >= 1000
        rows.append((name, text + (f"; {sr['failures'] + fsr['failures']} failed" if sr["failures"] + fsr["failures"]
                                   else ""), ok))
    return rows


def _stop_details(ur: dict[str, Any], dxl: dict[str, Any]) -> list[tuple[str, str]]:
    rows = []
    for label, res in (("UR", ur), ("DXL", dxl)):
        st = res["stop"]
        for part, values in st["parts_ms"].items():
            rows.append((f"{label} stop: {part}", _summary(values)))
        if st["failures"]:
            rows.append((f"{label} stop: failed", f"{len(st['failures'])}: {st['failures'][0]}"))
        if "held_position_age_ms" in st:
            rows.append((f"{label} stop: age of the Present Position held", _summary(st["held_position_age_ms"])))
        if "held_goal_minus_q_rad" in st:
            held = np.asarray(st["held_goal_minus_q_rad"]) * 1e3
            rows.append((f"{label} stop: |held goal - arm's q when the halt took effect|",
                         f"median {np.median(held):.2f} mrad, max {np.max(held):.2f} mrad"))
            rows.append((f"{label} stop: the arm was at the held goal ... before (fastest joint)",
                         _summary(st["held_goal_lag_ms"])))
    return rows


def run(json_path: str | Path | None = None, duration: float = 60.0, stops: int = 200) -> dict[str, Any]:
    """Measure, print a table, optionally write JSON; returns the numbers and the acceptance rows."""
    console = table_console()
    load = os.getloadavg()
    console.print(f"[bold]arm adapters[/bold]: UR receive for {duration:g} s, {stops} stops per arm, then the rest; "
                  f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} CPUs")
    with responsive_readers(), frozen_heap():  # as the monitor runs the adapters and their reflex
        ur = bench_ur(duration, stops)
        dxl = bench_dxl(duration, stops)
    rows = acceptance(ur, dxl)
    table = Table(title="ftc bench arms")
    table.add_column("acceptance")
    table.add_column("measured")
    table.add_column("ok")
    for name, value, ok in rows:
        table.add_row(name, value, "[green]yes[/green]" if ok else "[red]NO[/red]")
    console.print(table)
    details = Table(title="where the stop latency goes")
    details.add_column("part")
    details.add_column("measured")
    for name, value in _stop_details(ur, dxl):
        details.add_row(name, value)
    console.print(details)
    load_end = os.getloadavg()
    console.print(f"load average at the end {load_end[0]:.2f} {load_end[1]:.2f} {load_end[2]:.2f}")
    result = {"duration_s": duration, "stops": stops, "load_average": [load, load_end], "ur": ur, "dynamixel": dxl,
              "acceptance": [{"name": n, "measured": v, "ok": bool(o)} for n, v, o in rows]}
    if json_path is not None:
        Path(json_path).write_text(json.dumps(result, indent=2, default=float))
    return result

