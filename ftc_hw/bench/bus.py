"""Bus micro-benchmark (``ftc bench bus``): publish-to-deliver throughput and ``sample_at`` latency.

Throughput: ``frames`` pre-built :class:`WrenchFrame` are published on one topic from one thread; a
configuration's figure is frames per second from the first publish until every subscriber has
received every frame (callback subscribers: a no-op Python callback; queue subscribers: one consumer
thread each calling ``get``, queues large enough not to drop). The median of ``repeat`` runs is kept.

Latency: ``sample_at`` on a joint topic holding 10 000 frames at 500 Hz (6 joints, with tau), at
uniformly random times, timed call by call.
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.table import Table

from ftc_hw.bus.bus import Bus
from ftc_hw.bus.frames import JointFrame, WrenchFrame

__all__ = ["run"]

_TOPIC = "wrench/bench"


def _wrench_frames(n: int) -> list[WrenchFrame]:
    w = np.zeros(6)
    w.flags.writeable = False
    return [WrenchFrame(i * 1_000_000, i * 1_000_000, i, "bench", w) for i in range(n)]


def _callback_fps(frames: list[WrenchFrame], n_subs: int) -> float:
    bus = Bus()

    def on_frame(frame: WrenchFrame) -> None:
        pass

    subs = [bus.subscribe(_TOPIC, on_frame) for _ in range(n_subs)]
    publish = bus.publish
    t0 = time.perf_counter()
    for f in frames:
        publish(_TOPIC, f)
    dt = time.perf_counter() - t0
    if any(s.delivered != len(frames) for s in subs):
        raise RuntimeError(f"lost frames: {[s.delivered for s in subs]} of {len(frames)}")
    return len(frames) / dt


def _queue_fps(frames: list[WrenchFrame], n_subs: int) -> float:
    bus = Bus()
    n = len(frames)
    subs = [bus.subscribe(_TOPIC, maxsize=n) for _ in range(n_subs)]
    received = [0] * n_subs

    def consume(k: int) -> None:
        get = subs[k].get
        for _ in range(n):
            get(10.0)
        received[k] = n

    threads = [threading.Thread(target=consume, args=(k,), daemon=True) for k in range(n_subs)]
    for t in threads:
        t.start()
    publish = bus.publish
    t0 = time.perf_counter()
    for f in frames:
        publish(_TOPIC, f)
    for t in threads:
        t.join()
    dt = time.perf_counter() - t0
    if received != [n] * n_subs or any(s.drops for s in subs):
        raise RuntimeError(f"lost frames: received {received}, drops {[s.drops for s in subs]}")
    return n / dt


def _publish_only_fps(frames: list[WrenchFrame]) -> float:
    bus = Bus()
    publish = bus.publish
    t0 = time.perf_counter()
    for f in frames:
        publish(_TOPIC, f)
    return len(frames) / (time.perf_counter() - t0)


def _sample_at_us(n_frames: int = 10_000, rate_hz: float = 500.0, calls: int = 20_000) -> dict[str, float]:
    bus = Bus()
    rng = np.random.default_rng(0)
    period_ns = round(1e9 / rate_hz)
    for i in range(n_frames):
        q, qd, cur, tau = rng.normal(size=(4, 6))
        bus.publish("joints/bench", JointFrame.make(i * period_ns, q, qd, cur, tau, source="bench", seq=i))
    times = rng.integers(0, (n_frames - 1) * period_ns, calls).tolist()
    sample_at, clock = bus.sample_at, time.perf_counter_ns
    lat = np.empty(calls)
    for k, t in enumerate(times):
        t0 = clock()
        sample_at("joints/bench", t)
        lat[k] = clock() - t0
    return {"median": float(np.median(lat)) / 1e3, "p99": float(np.percentile(lat, 99)) / 1e3}


def run(
    json_path: Path | None = None, frames: int = 200_000, *, repeat: int = 3, quiet: bool = False,
    transport: str = "inproc",
) -> dict:
    """Run the benchmark, print a table (unless ``quiet``), write JSON if ``json_path``; return the dict.
    ``transport="zenoh"`` adds the bus between processes (:mod:`ftc_hw.bench.bus_remote`)."""
    fr = _wrench_frames(frames)

    def median_of(fn: Any, *args: Any) -> float:
        return statistics.median(fn(*args) for _ in range(repeat))

    result: dict[str, Any] = {
        "frames": frames,
        "repeat": repeat,
        "publish_only_fps": median_of(_publish_only_fps, fr),
        "publish_deliver_fps": {
            "1_sub_callback": median_of(_callback_fps, fr, 1),
            "1_sub_queue": median_of(_queue_fps, fr, 1),
            "4_sub_callback": median_of(_callback_fps, fr, 4),
            "4_sub_queue": median_of(_queue_fps, fr, 4),
        },
        "sample_at_us": _sample_at_us(),
        "python": f"{platform.python_implementation()} {platform.python_version()}",
        "machine": f"{platform.machine()} {platform.system()} {platform.release()}, {os.cpu_count()} CPU",
        "numpy": np.__version__,
    }
    if transport == "zenoh":
        from ftc_hw.bench.bus_remote import measure  # lazy: spawns processes, loads Zenoh

        result["zenoh"] = measure(frames=min(frames, 100_000))
    if not quiet:
        _print(result)
    if json_path is not None:
        Path(json_path).write_text(json.dumps(result, indent=2) + "\n")
    return result


def _print(result: dict) -> None:

    table = Table(title=f"bus bench ({result['frames']} frames, median of {result['repeat']})")
    table.add_column("measure")
    table.add_column("value", justify="right")
    table.add_row("publish only, no subscriber", f"{result['publish_only_fps']:,.0f} frames/s")
    for key, fps in result["publish_deliver_fps"].items():
        table.add_row(f"publish->deliver, {key.replace('_', ' ')}", f"{fps:,.0f} frames/s")
    table.add_row("sample_at median", f"{result['sample_at_us']['median']:.1f} us")
    table.add_row("sample_at p99", f"{result['sample_at_us']['p99']:.1f} us")
    zenoh = dict(result.get("zenoh", {}))
    raw = zenoh.pop("raw", {})
    for n, r in zenoh.items():
        t, lat = r["throughput"], r["latency"]
        table.add_row(f"zenoh, 2 processes, {n.replace('_', ' ')}, flat out",
                      f"{t['frames_per_s']:,.0f} frames/s ({t['received_min']:,} of {t['frames']:,} delivered)")
        table.add_row(f"zenoh, {n.replace('_', ' ')}, publish->deliver at 1 kHz",
                      f"median {lat['latency_us']['median']:.0f} us, p99 {lat['latency_us']['p99']:.0f} us, "
                      f"max {lat['latency_us']['max']:.0f} us ({lat['received_min']:,} of {lat['frames']:,})")
    for what, r in raw.items():
        lat = r["latency_us"]
        table.add_row(f"zenoh alone (no ftc code), {'at 1 kHz' if what == 'paced' else 'one every 20-60 ms, express'}",
                      f"median {lat['median']:.0f} us, p99 {lat['p99']:.0f} us, max {lat['max']:.0f} us "
                      f"({r['received']:,} of {r['messages']:,})")
    table.add_row("python", result["python"])
    table.add_row("machine", result["machine"])
    Console(file=sys.stdout).print(table)
