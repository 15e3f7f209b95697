"""F/T device benchmark (``ftc bench devices``): each acceptance figure of the device layer, measured on
the physics world in real time, through the emulators (separate processes) and the real client
libraries.

Sections (``duration`` s each where the acceptance names a duration, shorter where it does not):

* FT 300 stream over emulated Modbus RTU: rate from receive times; a second FT 300 on the same world
  with 1 % of its stream frames corrupted: corrupted frames published (every published wrench is
  checked against the world's samples) and corruptions counted against the emulator's count.
* FT 300 over Modbus TCP: polls per second, unpaced (``duration``/6 s, at most 10 s).
* 1 kHz serial stream and CAN F/T: ``duration`` s clean (samples lost, values checked by sequence
  number against the world), then ``duration``/3 s (at most 20 s) with frames dropped and corrupted:
  are the reported gaps exactly the destroyed samples?
* Kill and restart of each emulator (``trials`` times): stale-event latency after the kill, first
  frame after the device's return (its ``ready_ns``), frames received during the dead period.
"""
from __future__ import annotations

import json
import os
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from tempfile import TemporaryDirectory
from typing import Any

import numpy as np
from rich.table import Table

from ftc_hw.app.setup.rig import Rig, build_rig
from ftc_hw.bench.report import table_console
from ftc_hw.bus import EVENTS_DEVICE, Bus, WrenchFlag
from ftc_hw.scene import DeviceSpec, Scene, load_scene
from ftc_hw.sim_devices.emulator import sample_number
from ftc_hw.sim_devices.host import WorldHost

__all__ = ["run"]


@dataclass
class _World:
    host: WorldHost
    tmp: Path
    samples: dict[int, np.ndarray] = field(default_factory=dict)  # world sample index -> wrench
    _stop: threading.Event = field(default_factory=threading.Event)

    @property
    def scene(self) -> Scene:
        return self.host.scene

    def pace(self) -> tuple[float, float]:
        """(wall clock, world time): two of them give the world's pace, which the devices follow."""
        return time.monotonic(), self.host.sim_time()

    def stream(self, rig: Rig, seconds: float) -> float:
        """The rig connected and streaming for ``seconds``, then closed (and 0.3 s for the emulators'
        stats files to catch up); returns the world's pace over it (world s per wall s)."""
        with rig:
            p0 = self.pace()
            time.sleep(seconds)
            p1 = self.pace()
        time.sleep(0.3)
        return (p1[1] - p0[1]) / (p1[0] - p0[0])

    def sample_number(self, t: float) -> int:
        return sample_number(t, self.scene.sensor.rate_hz)

    def rig(self, *specs: DeviceSpec, bus: Bus | None = None) -> Rig:
        """The adapters of these emulated devices (not opened; ``with`` opens them and waits 10 s)."""
        return build_rig(self.scene, bus=bus, devices=specs, endpoints=self.host.endpoints, timeout=10.0)

    def stats(self, name: str) -> dict[str, Any]:
        p = self.tmp / f"{name}.json"
        return json.loads(p.read_text()) if p.exists() else {}


def _options(tmp: Path, spec: DeviceSpec, **options: Any) -> dict[str, Any]:
    return {"path": str(tmp / f"{spec.name}.tty"), "stats_path": str(tmp / f"{spec.name}.json"), **options}


@contextmanager
def _world(scene: Scene, seconds: float, tmp: Path, emulate: list[tuple[DeviceSpec, dict[str, Any]]],
           scenario: str = "static-pokes") -> Iterator[_World]:
    """The scene's physics world in its own process, in real time, emulating ``emulate`` ((spec,
    emulator options) pairs), and a record of every F/T sample it produces."""
    host = WorldHost(scene, scenario, devices=[spec for spec, _ in emulate], duration=seconds + 60.0,
                     options={spec.name: _options(tmp, spec, **opts) for spec, opts in emulate})
    host.start()
    w = _World(host, tmp)
    reader = host.ft_reader(from_start=True)

    def collect() -> None:
        while not w._stop.wait(0.05):
            for rec in reader.new():
                w.samples[w.sample_number(float(rec[0]))] = rec[1:7].copy()

    collector = threading.Thread(target=collect, daemon=True)
    collector.start()
    try:
        yield w
    finally:
        w._stop.set()
        collector.join(10)
        host.close()


def _spec(scene: Scene, kind: str, name: str | None = None, transport: str | None = None, **params) -> DeviceSpec:
    d = next(d for d in scene.devices if d.kind == kind)
    return DeviceSpec(name or d.name, d.kind, transport or d.transport, d.address, {**d.params, **params})


def _rate(frames) -> float:
    if len(frames) < 2:
        return 0.0
    return (len(frames) - 1) / ((frames[-1].t_host_ns - frames[0].t_host_ns) / 1e9)


def _counts(w: np.ndarray, lsb: np.ndarray) -> tuple[int, ...]:
    return tuple(int(x) for x in np.round(np.asarray(w) / lsb))


# -- sections ---------------------------------------------------------------------------------------
def _ft300(duration: float, tmp: Path) -> dict[str, Any]:
    lsb = np.array([0.01] * 3 + [0.001] * 3)
    scene = load_scene("dxl-arm")
    clean = _spec(scene, "ft300")
    noisy = _spec(scene, "ft300", name="ft_corrupt")
    with _world(scene, duration, tmp, [(clean, {}), (noisy, {"faults": {"corrupt": 0.01}, "seed": 1})]) as w:
        rig = w.rig(clean, noisy)
        pace = w.stream(rig, duration)
        stats = w.stats(noisy.name)
        known = {_counts(x, lsb) for x in dict(w.samples).values()}  # the collector is still running
    out: dict[str, Any] = {}
    for a in rig.adapters:
        frames = rig.bus.history(a.topic)
        bad = sum(_counts(f.wrench, lsb) not in known for f in frames)
        out[a.name] = {"frames": len(frames), "rate_hz": _rate(frames), "corrupted_published": bad,
                       "checksum_errors": a.counters["checksum_errors"]}
    out["world_pace"] = pace
    inj = stats.get("faults", {})
    out["ft_corrupt"]["corrupted_injected"] = inj.get("stream.corrupt", 0)
    out["ft_corrupt"]["stream_frames_sent"] = stats.get("samples", 0)
    return out


def _modbus_tcp(seconds: float, tmp: Path) -> dict[str, Any]:
    scene = load_scene("dxl-arm")
    spec = _spec(scene, "ft300", transport="modbus-tcp", poll_hz=0)
    with _world(scene, seconds, tmp, [(spec, {})]) as w, w.rig(spec) as rig:
        a = rig.adapter(spec.name)
        n0, t0 = a.counters["polls"], time.monotonic()
        time.sleep(seconds)
        n1, t1 = a.counters["polls"], time.monotonic()
    return {"polls_per_s": (n1 - n0) / (t1 - t0), "timeouts": a.counters["timeouts"], "seconds": t1 - t0}


_STREAMS = {  # scene, kind, LSB of the device encoding
    "serial_1k": ("leng2016", "ft-serial-stream", np.array([1e-4] * 3 + [1e-5] * 3)),
    "can_1k": ("ur5e", "ft-can", np.array([1e-3] * 6)),
}


def _stream(key: str, seconds: float, tmp: Path, faults: dict | None = None) -> dict[str, Any]:
    scene_name, kind, lsb = _STREAMS[key]
    scene = load_scene(scene_name)
    spec = _spec(scene, kind)
    with _world(scene, seconds, tmp, [(spec, {"faults": faults, "seed": 3} if faults else {})]) as w:
        rig = w.rig(spec, bus=Bus(history=int(seconds * 1100) + 1000))  # keep every frame of the run
        a = rig.adapter(spec.name)
        pace = w.stream(rig, seconds)
        stats = w.stats(spec.name)
        frames = rig.bus.history(a.topic)
        world = dict(w.samples)
    seqs = [f.seq for f in frames]
    missing = set(range(seqs[0], seqs[-1] + 1)) - set(seqs) if seqs else set()
    mismatched = int(sum(f.seq not in world or np.any(np.abs(f.wrench - world[f.seq]) > 0.51 * lsb) for f in frames))
    world_hz = pace * scene.sensor.rate_hz
    out = {"frames": len(frames), "seconds": seconds, "rate_hz": _rate(frames), "world_rate_hz": world_hz,
           "lost": len(missing),
           "seq_gaps": a.counters["seq_gaps"], "mismatched_values": mismatched,
           "checksum_errors": a.counters["checksum_errors"]}
    if faults:
        damaged = {n for n in stats.get("damaged", []) if seqs and seqs[0] <= n <= seqs[-1]}
        flagged = {f.seq for f in frames if f.flags & WrenchFlag.SEQ_GAP}
        reported = {first + i for first, n in a.gaps for i in range(n)}
        after_gaps = {n + 1 for n in missing if n + 1 not in missing}
        out.update(injected=stats.get("faults", {}), destroyed=len(damaged),
                   gaps_exact=missing == damaged == reported and flagged == after_gaps)
    return out


_RECONNECT = {  # scene, kind, transport
    "ft-serial-stream": ("leng2016", "ft-serial-stream", None),
    "ft-can": ("ur5e", "ft-can", None),
    "ft300 stream (RTU)": ("dxl-arm", "ft300", None),
    "ft300 poll (TCP)": ("dxl-arm", "ft300", "modbus-tcp"),
}


def _reconnect(label: str, trials: int, tmp: Path, dead_s: float = 1.0) -> dict[str, Any]:
    scene_name, kind, transport = _RECONNECT[label]
    scene = load_scene(scene_name)
    spec = _spec(scene, kind, transport=transport)
    stale_ms, back_ms, dead_frames = [], [], 0
    with _world(scene, trials * (dead_s + 4.0), tmp, [(spec, {})]) as w:
        endpoint = w.host.endpoint(spec.name)
        keep = _options(tmp, spec, **({"port": endpoint["port"]} if "port" in endpoint else {}))
        rig = w.rig(spec)
        bus, a = rig.bus, rig.adapter(spec.name)
        events = bus.subscribe(EVENTS_DEVICE, maxsize=None)
        with rig:
            for _ in range(trials):
                time.sleep(1.0)
                events.drain()
                t_kill = time.monotonic_ns()
                w.host.kill(spec.name)
                time.sleep(dead_s)
                t_restart = time.monotonic_ns()
                t_back = w.host.restart(spec.name, keep)["ready_ns"]
                deadline = time.monotonic() + 5.0
                while not bus.window(a.topic, t_back, time.monotonic_ns()) and time.monotonic() < deadline:
                    time.sleep(0.002)
                first = bus.window(a.topic, t_back, time.monotonic_ns())
                stale = [e for e in events.drain() if e.kind == "stale" and e.source == a.name]
                stale_ms.append((stale[0].t_host_ns - t_kill) / 1e6 if stale else float("inf"))
                back_ms.append((first[0].t_host_ns - t_back) / 1e6 if first else float("inf"))
                dead_frames += len(bus.window(a.topic, t_kill + 20_000_000, t_restart))
    return {"trials": trials, "dead_s": dead_s, "stale_ms_max": max(stale_ms), "stale_ms": stale_ms,
            "reconnect_ms_max": max(back_ms), "reconnect_ms": back_ms, "dead_period_frames": dead_frames}


# -- entry point ------------------------------------------------------------------------------------
SECTIONS = ("ft300", "modbus_tcp", "serial_1k", "can_1k", "reconnect")


def run(json_path: Path | str | None = None, duration: float = 60.0, *, trials: int = 3, quiet: bool = False,
        sections: tuple[str, ...] | list[str] = SECTIONS) -> dict[str, Any]:
    """Run the ``sections``, print a table (unless ``quiet``), write JSON if ``json_path``; return the dict."""
    unknown = set(sections) - set(SECTIONS)
    if unknown:
        raise ValueError(f"unknown section(s) {sorted(unknown)} (known: {', '.join(SECTIONS)})")
    started = time.monotonic()
    res: dict[str, Any] = {"duration_s": duration, "load_avg_start": os.getloadavg()[0]}
    with TemporaryDirectory(prefix="ftc-bench-") as d:
        tmp = Path(d)
        if "ft300" in sections:
            res["ft300"] = _ft300(duration, tmp)
        if "modbus_tcp" in sections:
            res["modbus_tcp"] = _modbus_tcp(min(10.0, max(1.0, duration / 6)), tmp)
        gap_s = min(20.0, max(1.0, duration / 3))
        faults = {"drop": 0.005, "corrupt": 0.005}
        for key in _STREAMS:
            if key in sections:
                res[key] = _stream(key, duration, tmp)
                res[key + "_gaps"] = _stream(key, gap_s, tmp, faults)
        if "reconnect" in sections:
            res["reconnect"] = {label: _reconnect(label, trials, tmp) for label in _RECONNECT}
    res["wall_s"] = time.monotonic() - started
    res["load_avg_end"] = os.getloadavg()[0]
    if json_path is not None:
        Path(json_path).write_text(json.dumps(res, indent=2, default=float) + "\n")
    if not quiet:
        _print(res)
    return res


def _print(res: dict[str, Any]) -> None:

    ok = "[green]yes[/]"
    no = "[red]NO[/]"
    t = Table(title=f"device bench ({res['duration_s']:g} s per acceptance run, {res['wall_s']:.0f} s in all; "
                    f"load average {res['load_avg_start']:.1f} -> {res['load_avg_end']:.1f})")
    for col in ("acceptance", "measured", "target", "met"):
        t.add_column(col)
    if "ft300" in res:
        f3 = res["ft300"]
        rate = f3["ft"]["rate_hz"]
        t.add_row("FT 300 stream rate over RTU", f"{rate:.2f} Hz ({f3['ft']['frames']} frames; world pace "
                  f"{f3['world_pace']:.4f})", "100 Hz +- 1 %", ok if 99.0 <= rate <= 101.0 else no)
        c = f3["ft_corrupt"]
        t.add_row("FT 300, 1 % corrupted: published corrupted", str(c["corrupted_published"]), "0",
                  ok if c["corrupted_published"] == 0 else no)
        t.add_row("FT 300, 1 % corrupted: counted / injected",
                  f"{c['checksum_errors']} / {c['corrupted_injected']} of {c['stream_frames_sent']}", "equal",
                  ok if c["checksum_errors"] == c["corrupted_injected"] else no)
    if "modbus_tcp" in res:
        pps = res["modbus_tcp"]["polls_per_s"]
        t.add_row("Modbus TCP polling", f"{pps:.0f} reads/s", ">= 200 reads/s", ok if pps >= 200 else no)
    for key, label in (("serial_1k", "1 kHz serial"), ("can_1k", "CAN F/T")):
        if key not in res:
            continue
        s = res[key]
        t.add_row(f"{label}: lost in {s['seconds']:g} s",
                  f"{s['lost']} of {s['frames']} ({s['rate_hz']:.1f} Hz; world {s['world_rate_hz']:.1f} Hz), "
                  f"{s['mismatched_values']} wrong values",
                  "0", ok if s["lost"] == 0 and s["mismatched_values"] == 0 else no)
        g = res[key + "_gaps"]
        t.add_row(f"{label}: gaps where injected ({g['seconds']:g} s)",
                  f"{g['seq_gaps']} gaps, {g['lost']} lost / {g['destroyed']} destroyed", "exact",
                  ok if g["gaps_exact"] and g["mismatched_values"] == 0 else no)
    for label, r in res.get("reconnect", {}).items():
        t.add_row(f"kill/restart {label}: stale", f"{r['stale_ms_max']:.0f} ms (max of {r['trials']})", "<= 100 ms",
                  ok if r["stale_ms_max"] <= 100 else no)
        t.add_row(f"kill/restart {label}: reconnect", f"{r['reconnect_ms_max']:.0f} ms after return", "<= 1000 ms",
                  ok if r["reconnect_ms_max"] <= 1000 else no)
        t.add_row(f"kill/restart {label}: frames from the dead period", str(r["dead_period_frames"]), "0",
                  ok if r["dead_period_frames"] == 0 else no)
    table_console().print(t)
