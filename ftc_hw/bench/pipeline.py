"""``ftc bench pipeline``: what the whole pipeline costs per F/T frame at a sensor rate, stage by stage.

Offline leg (one thread, no world running beside it): the world records ``seconds`` of the collision
sweep at the scene's sensor rate (:func:`ftc_hw.bench.compensation.record`), and every sample goes
through what the live monitor runs for it:

* ``reader``: the F/T adapter's own work for one record. RDT (``ft-rdt``): the datagram through a
  loopback UDP socket, ``recvmsg``, decode, counts to SI, ``publish_sample`` (sequence, clock
  alignment, bus publish). Other kinds: ``publish_sample`` only (their decode is not included).
* ``monitor``: :meth:`LiveMonitor.handle` less the pipeline: the F/T clock alignment, the joint state
  interpolated at the frame's time, the pipeline input published.
* the pipeline's stages, timed through the pipeline's clock (:mod:`.pipeline_stages`):
  ``compensation`` (acceleration estimate, lag model, loads, contact wrench), ``detection``,
  ``localization`` (joint torques and solves, frames in contact only), ``events`` (the contact's
  track, events, their point on the meshes); ``pipeline`` is the whole ``process`` call, timed in a
  second pass by a clock without stage laps;
``pipeline cpu`` the same call's thread CPU time (what issue 24's per-frame target is about, less the
time other processes held the core).

Per stage: median, p99 and max over frames (wall time, us). ``total`` = reader + monitor + pipeline per
frame; ``cpu`` the same pass's thread CPU time (less sensitive to other processes on the host: time a
thread spends preempted is not in it). ``capacity``: frames per second one core sustains at the
mean total; ``core share``: the rate times the mean total. Detection: onsets against the world's
contacts; ``detect ms``: from the first contact sample to the end of the frame that emitted the onset
(sample times plus that frame's cost; the reflex's stop call is not in it: the real-time leg measures it).

Real-time leg (``realtime_s`` > 0, :mod:`.pipeline_live`): ``ftc monitor --sim`` with the stop reflex
(a UR arm's operator resuming after each stop) and a recording, its frames lost and judged, CPU share,
onset delay and stop latency, and the recording's replay.
"""
from __future__ import annotations

import json
import os
import platform
import socket
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from rich.table import Table

from ftc_hw.bench.compensation import Recording, _episodes, arm_rate, record
from ftc_hw.bench.pipeline_stages import FrameClock, StageTimer, summarize_us
from ftc_hw.bench.process_cpu import HOST, SELF
from ftc_hw.bench.report import table_console
from ftc_hw.bus import Bus, JointFrame, WrenchFlag, WrenchFrame, wrench_topic
from ftc_hw.codecs.netft_rdt import RdtRecord, encode_records
from ftc_hw.devices.base import frozen_heap
from ftc_hw.devices.ft_base import FTAdapter
from ftc_hw.devices.netft_rdt import RdtFTAdapter
from ftc_hw.devices.registry import role_of
from ftc_hw.monitor import LiveMonitor
from ftc_hw.pipeline import STAGES
from ftc_hw.scene import Scene, load_scene

HOST_EPOCH_NS = 10**12  # host time of the world's t = 0
DELIVERY_NS = 150_000  # a frame's receive time after its device time (the aligners see a constant delay)
COUNTS_PER_UNIT = 1_000_000.0  # RDT counts per N and per N m in the reader leg


def scene_at(name: str, rate_hz: float | None) -> Scene:
    """The scene with its sensor (and F/T device) at ``rate_hz`` (None: its own)."""
    scene = load_scene(name)
    if rate_hz is None or rate_hz == scene.sensor.rate_hz:
        return scene
    devices = [replace(d, params={**d.params, "rate_hz": float(rate_hz)}) if role_of(d.kind) == "ft" and
               "rate_hz" in d.params else d for d in scene.devices]
    return replace(scene, sensor=replace(scene.sensor, rate_hz=float(rate_hz)), devices=devices)


# -- the reader's leg ---------------------------------------------------------------------------------
def reader_costs(scene: Scene, rec: Recording) -> tuple[np.ndarray, str]:
    """Per record, ns: the F/T adapter's work (see the module doc); and what was timed."""
    ft = next(d for d in scene.devices if role_of(d.kind) == "ft")
    bus = Bus()
    sub = bus.subscribe(wrench_topic(ft.name), maxsize=None)
    if ft.kind == "ft-rdt":
        out = _rdt_reader_costs(ft.name, bus, scene.sensor.rate_hz, rec, sub)
        return out, "UDP recvmsg + decode + publish_sample"
    adapter = _PublishOnly(ft.name, bus, seq_period_ns=round(1e9 / scene.sensor.rate_hz))
    out = np.empty(len(rec.t), dtype=np.int64)
    for i, w in enumerate(rec.wrench):
        t0 = time.perf_counter_ns()
        adapter.publish_sample(w, t_host_ns=time.monotonic_ns(), seq=i)
        out[i] = time.perf_counter_ns() - t0
        if i % 1000 == 999:
            sub.drain()
    return out, "publish_sample (decode not included)"


class _PublishOnly(FTAdapter):
    """An F/T adapter without a device: only its ``publish_sample``."""

    def _connect(self) -> None:
        pass

    def _disconnect(self) -> None:
        pass

    def _read_once(self) -> None:
        pass


def _rdt_reader_costs(name: str, bus: Bus, rate_hz: float, rec: Recording, sub) -> np.ndarray:
    box = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    box.bind(("127.0.0.1", 0))
    adapter = RdtFTAdapter(name, bus, "127.0.0.1", port=box.getsockname()[1], read_calibration=False,
                           counts_per_force=COUNTS_PER_UNIT, counts_per_torque=COUNTS_PER_UNIT, rate_hz=rate_hz)
    out = np.empty(len(rec.t), dtype=np.int64)
    try:
        adapter._connect()
        _, client = box.recvfrom(64)  # the start request
        cal = adapter.calibration
        for i, w in enumerate(rec.wrench):
            box.sendto(encode_records([RdtRecord(i + 1, i, 0, cal.to_counts(w))]), client)
            t0 = time.perf_counter_ns()
            adapter._read_once()
            out[i] = time.perf_counter_ns() - t0
            if i % 1000 == 999:
                sub.drain()
    finally:
        adapter._disconnect()
        box.close()
    if adapter.counters["records"] != len(rec.t):
        raise RuntimeError(f"reader leg: {adapter.counters['records']} of {len(rec.t)} records received")
    return out


# -- the monitor's and the pipeline's leg ---------------------------------------------------------------
def _frames(scene: Scene, rec: Recording) -> tuple[list[WrenchFrame], list[list[JointFrame]]]:
    """The F/T frames, and before each the joint frames delivered by then (the sample after it included:
    the live monitor waits for the joint stream to pass a frame)."""
    step = max(1, round(scene.sensor.rate_hz / arm_rate(scene)))
    t_dev = np.round(rec.t * 1e9).astype(np.int64)
    joints: list[list[JointFrame]] = [[] for _ in t_dev]
    for m, j in enumerate(range(0, len(t_dev), step)):
        joints[max(0, j - step)].append(JointFrame.make(
            HOST_EPOCH_NS + int(t_dev[j]) + DELIVERY_NS, rec.q[j], rec.qd[j], rec.current[j], source="arm", seq=m,
            t_device_ns=int(t_dev[j])))
    ft = [WrenchFrame.make(HOST_EPOCH_NS + int(t) + DELIVERY_NS, w, source="ft", seq=i, t_device_ns=int(t),
                           flags=WrenchFlag.SATURATED if s else WrenchFlag.NONE)
          for i, (t, w, s) in enumerate(zip(t_dev, rec.wrench, rec.saturated, strict=True))]
    return ft, joints


def monitor_pass(scene: Scene, rec: Recording, staged: bool) -> dict[str, Any]:
    """Every frame through a fresh monitor: per frame ``handle`` and ``process`` wall ns, thread CPU ns,
    the stages' ns (``staged``), and the onsets (frame index)."""
    ft, joints = _frames(scene, rec)
    mon = LiveMonitor(Bus(), scene, tare_s=0.1)
    clock = StageTimer() if staged else FrameClock()
    mon.pipeline.clock = clock
    n = len(ft)
    handle, proc, proc_cpu, cpu = (np.zeros(n, dtype=np.int64) for _ in range(4))
    stages = np.zeros((n, len(STAGES)), dtype=np.int64)
    onsets: list[int] = []
    for i, frame in enumerate(ft):
        for jf in joints[i]:
            mon.on_joints(jf)
        clock.reset()
        c0, t0 = time.thread_time_ns(), time.perf_counter_ns()
        mf = mon.handle(frame)
        handle[i], cpu[i] = time.perf_counter_ns() - t0, time.thread_time_ns() - c0
        proc[i], proc_cpu[i] = clock.wall_ns, clock.cpu_ns
        if staged:
            stages[i] = clock.frame_times()
        if mf is not None and any(e.kind == "onset" for e in mf.result.events):
            onsets.append(i)
    judged = proc > 0
    return {"handle": handle[judged], "process": proc[judged], "process_cpu": proc_cpu[judged], "cpu": cpu[judged],
            "stages": stages[judged],
            "in_contact": rec.contact[judged], "onsets": onsets, "index": np.nonzero(judged)[0], "frames": n,
            "counters": dict(mon.counters)}


def detection(rec: Recording, onsets: list[int], handle_ns_at: dict[int, int]) -> dict[str, Any]:
    """Onsets against the world's contacts: detected, false alarms, ms from the first contact sample to the
    end of the onset frame's processing."""
    episodes = _episodes(rec.t, rec.contact, merge_s=0.02)
    delays, false_alarms = [], 0
    for i in onsets:
        if not any(a - 0.001 <= rec.t[i] <= b + 0.02 for a, b in episodes):
            false_alarms += 1
    for a, b in episodes:
        first = next((i for i in onsets if a - 0.001 <= rec.t[i] <= b), None)
        if first is not None:
            delays.append((rec.t[first] - a) * 1e3 + handle_ns_at.get(first, 0) / 1e6)
    return {"contacts": len(episodes), "detected": len(delays), "false_alarms": false_alarms,
            "detect_ms_median": float(np.median(delays)) if delays else float("nan"),
            "detect_ms_max": float(np.max(delays)) if delays else float("nan")}


def offline(scene: Scene, seconds: float, seed: int, speed: float) -> dict[str, Any]:
    t0 = time.monotonic()
    rec = record(scene, "sweep-with-collision", seconds, speed, seed)
    recorded_s = time.monotonic() - t0
    with frozen_heap():
        reader, reader_what = reader_costs(scene, rec)
    with frozen_heap():  # as the live monitor runs: no full collection walks the set-up heap
        staged = monitor_pass(scene, rec, staged=True)
        plain = monitor_pass(scene, rec, staged=False)
    rate = scene.sensor.rate_hz
    total = reader[plain["index"]] + plain["handle"]
    stage_rows = {"reader": summarize_us(reader), "monitor": summarize_us(staged["handle"] - staged["process"])}
    for k, name in enumerate(STAGES):
        col = staged["stages"][:, k]
        stage_rows[name] = summarize_us(col[staged["in_contact"]] if name == "localization" else col)
    stage_rows["pipeline"] = summarize_us(plain["process"])
    stage_rows["pipeline cpu"] = summarize_us(plain["process_cpu"])
    stage_rows["total"] = summarize_us(total)
    stage_rows["cpu"] = summarize_us(reader[plain["index"]] + plain["cpu"])
    mean_us = float(total.mean()) / 1e3
    handle_at = dict(zip(plain["index"].tolist(), plain["handle"].tolist(), strict=True))
    return {"rate_hz": rate, "seconds": seconds, "frames": plain["frames"], "judged": int(plain["index"].size),
            "reader_timed": reader_what, "stages_us": stage_rows, "capacity_hz": 1e6 / mean_us,
            "core_share": rate * mean_us / 1e6, "period_us": 1e6 / rate,
            "detection": detection(rec, plain["onsets"], handle_at), "record_s": recorded_s,
            "monitor_counters": plain["counters"]}



# -- the command ------------------------------------------------------------------------------------------
DEFAULT_SCENES = ("ur5e", "ur5e-netft")
ROWS = ("reader", "monitor", *STAGES, "pipeline", "pipeline cpu", "total", "cpu")


@dataclass(frozen=True)
class RealtimeLeg:
    """The real-time leg's run: ``seconds`` of the sweep; ``ahead``: the world computed first and played to the
    emulators (``--world-ahead``), else the live world; ``reality``: the world's arm, sensor and shell against
    the model (docs/reality.md); ``calibration``: the monitor's (``ftc identify``'s of that world; None: the
    scene's nominal model); ``split_cores``: the cell's processes on one core, the monitor on the others
    (:mod:`ftc_hw.bench.cores`; shared where the host cannot split)."""

    seconds: float = 10.0
    ahead: bool = True
    reality: str = "ideal"
    calibration: Path | None = None
    split_cores: bool = False


def run(json_path: Path | None = None, scenes: list[str] | None = None, rate_hz: float | None = None,
        seconds: float = 20.0, seed: int = 0, speed: float = 1.0, realtime: RealtimeLeg | None = None) -> dict:
    """``rate_hz``: every scene's sensor at this rate (None: each its own; the world must step at a
    divisor of its period). ``realtime``: the real-time leg (None: the default :class:`RealtimeLeg`; its
    ``seconds`` 0: the offline leg only). It runs each scene at its own rate, and only when ``rate_hz`` is
    that rate. The offline leg is always the ideal world."""
    realtime = realtime or RealtimeLeg()
    console = table_console()
    results: dict[str, Any] = {}
    for name in scenes or DEFAULT_SCENES:
        scene = scene_at(name, rate_hz)
        entry: dict[str, Any] = {"load_1min_before": os.getloadavg()[0]}
        entry["offline"] = offline(scene, seconds, seed, speed)
        entry["load_1min_after"] = os.getloadavg()[0]
        if realtime.seconds > 0 and scene.sensor.rate_hz == load_scene(name).sensor.rate_hz:
            from ftc_hw.bench.pipeline_live import live  # lazy: the world and its emulators

            entry["realtime"] = live(name, realtime, seed)
        results[f"{name}@{scene.sensor.rate_hz:g}"] = entry
    results["meta"] = {"seconds": seconds, "realtime_s": realtime.seconds, "seed": seed, "speed": speed,
                       "ahead": realtime.ahead, "reality": realtime.reality,
                       "calibration": str(realtime.calibration) if realtime.calibration else None,
                       "split_cores": realtime.split_cores,
                       "python": platform.python_version(), "cpus": os.cpu_count()}
    console.print(_stage_table(results))
    console.print(_summary_table(results))
    if json_path is not None:
        json_path.write_text(json.dumps(results, indent=2, default=_jsonable))
    return results


def _jsonable(x: Any) -> Any:
    return x.tolist() if isinstance(x, np.ndarray) else str(x)


def _stage_table(results: dict) -> Table:
    keys = [k for k in results if k != "meta"]
    table = Table(title="ftc bench pipeline: cost per F/T frame, us (median / p99 / max; offline leg, wall time; "
                        "localization: frames in contact only)")
    table.add_column("stage")
    for k in keys:
        r = results[k]
        table.add_column(f"{k} (period {r['offline']['period_us']:.0f} us; load "
                         f"{r['load_1min_before']:.1f}-{r['load_1min_after']:.1f})", justify="right")
    for row in ROWS:
        cells = []
        for k in keys:
            s = results[k]["offline"]["stages_us"][row]
            cells.append(f"{s['median']:.1f} / {s['p99']:.1f} / {s['max']:.0f}")
        table.add_row(row, *cells)
    return table


def _summary_table(results: dict) -> Table:
    table = Table(title="ftc bench pipeline: keeping up (offline: capacity and detection; real time: ftc monitor "
                        "--sim with the stop reflex; world: computed ahead or live; stops: sent after the onset, after "
                        "the arrival of the frame that decided it (the monitor's own share), and at the arm's "
                        "interface after the contact's first sample; CPU: cores per process)")
    for c in ("scene@Hz", "capacity Hz", "core share", "detected", "false alarms", "detect ms (med)",
              "rt world, load", "rt sent", "rt received", "rt lost", "rt judged", "rt not judged", "rt detected",
              "rt onset ms", "rt stops: ms med/p99/max", "rt after arrival", "rt at arm: ms med/p99/max", "rt CPU",
              "rt arm missed",
              "rt recorded, replay"):
        table.add_column(c, justify="left" if c == "scene@Hz" else "right")
    for k, r in results.items():
        if k == "meta":
            continue
        o, d = r["offline"], r["offline"]["detection"]
        cells = [k, f"{o['capacity_hz']:.0f}", f"{o['core_share']:.2f}", f"{d['detected']}/{d['contacts']}",
                 f"{d['false_alarms']}", f"{d['detect_ms_median']:.2f}"]
        rt = r.get("realtime")
        if rt is None:
            cells += ["-"] * 14
        else:
            lost = (rt["sent"] - rt["received"]) if rt["sent"] is not None else rt["seq_lost"]
            cells += [f"{rt['world']} {rt['reality']}, {rt['load_1min']:.1f}",
                      f"{rt['sent'] if rt['sent'] is not None else '-'}",
                      f"{rt['received']}", f"{lost}", f"{rt['judged']}",
                      f"{rt['not_judged']} ({100 * rt['not_judged_share']:.0f} %)",
                      f"{rt['detected']}/{rt['contacts']} ({rt['false_alarms']} false)" if rt["evaluated"] else "-",
                      f"{rt['onset_delay_ms_median']:.2f}",
                      f"{rt['stops']}: {rt['stop_after_onset_ms_median']:.2f} / {rt['stop_after_onset_ms_p99']:.2f}"
                      f" / {rt['stop_after_onset_ms_max']:.2f}",
                      f"{rt['stops_timed_from_arrival']}: {rt['stop_after_arrival_ms_median']:.2f} / "
                      f"{rt['stop_after_arrival_ms_p99']:.2f} / {rt['stop_after_arrival_ms_max']:.2f}",
                      f"{rt['stops_at_arm']}: {rt['stop_at_arm_ms_median']:.2f} / {rt['stop_at_arm_ms_p99']:.2f}"
                      f" / {rt['stop_at_arm_ms_max']:.2f}",
                      _cpu_cell(rt["cpu_by_process"]), f"{rt['arm_missed']}",
                      f"{rt['recorded_inputs']} inputs, {rt['recorder_drops']} dropped; "
                      + ("identical" if rt["replay_identical"] else "DIFFERS")]
        table.add_row(*cells)
    return table


def _cpu_cell(shares: dict[str, float]) -> str:
    """Cores per process over the scenario, this one (the monitor) first, the host's busy cores last."""
    host = shares.get(HOST)
    rest = sorted((k, v) for k, v in shares.items() if k not in (SELF, HOST))
    parts = [f"{SELF} {shares.get(SELF, float('nan')):.2f}"] + [f"{k} {v:.2f}" for k, v in rest]
    return "; ".join(parts + ([f"host {host:.2f}"] if host is not None else []))
