"""``ftc bench bus --transport zenoh``: the bus between processes on Zenoh (:mod:`ftc_hw.bus.remote`).

One publisher (this process: a bus whose wrench topic a :class:`RemotePublisher` forwards) and 1 or
4 subscriber processes (each a Zenoh session into its own bus through a :class:`RemoteSubscriber`,
a no-op callback subscriber on the topic), on loopback TCP:

- throughput: ``frames`` frames published flat out; frames per second from the first publish to the
  last frame delivered into the slowest subscriber's bus, and how many arrived;
- latency: ``latency_frames`` frames paced at ``rate_hz``; publish (the frame's ``t_host_ns``, stamped
  when it is made) to delivery into the subscriber's bus (``time.monotonic_ns()``, one clock on one
  host): median, p99 and max.

Beside them, the transport's own floor on this host (``raw``): Zenoh alone, no ftc code on either side
(a bytes payload of an encoded wrench frame's size carrying its put time, a Python callback taking
the arrival time), between the same two kinds of process: at ``rate_hz`` as the latency run, and
sporadic (one message every 20-60 ms, express, as the stop reflex's commands go: each one wakes
sleeping threads on both sides).
"""
from __future__ import annotations

import contextlib
import multiprocessing as mp
import random
import struct
import time
from typing import Any

import numpy as np
import zenoh

from ftc_hw.bus.bus import Bus
from ftc_hw.bus.frames import WrenchFrame
from ftc_hw.bus.remote import RemotePublisher, RemoteSubscriber, free_loopback_endpoint, open_session
from ftc_hw.bus.wire import encode

_RIG, _TOPIC = "bench", "wrench/bench"
_RAW_KEY = "ftc/bench/raw"


def _subscriber(endpoint: str, expect: int, ready: Any, out: Any) -> None:
    """A subscriber process: every frame's delivery latency (ns) and when the last one arrived."""
    session = open_session(connect=[endpoint])
    bus = Bus(history=1000)
    lat = np.zeros(expect, dtype=np.int64)
    got = [0, 0]  # frames, monotonic ns of the last

    def on_frame(f: WrenchFrame) -> None:
        now = time.monotonic_ns()
        if got[0] < expect:
            lat[got[0]] = now - f.t_host_ns
        got[0] += 1
        got[1] = now

    bus.subscribe(_TOPIC, on_frame)
    sub = RemoteSubscriber(session, bus, _RIG)
    ready.set()
    end = time.monotonic() + 120.0
    while got[0] < expect and time.monotonic() < end:
        time.sleep(0.01)
    time.sleep(0.2)  # stragglers beyond the expected count would show up in the count
    out.put({"received": got[0], "t_last_ns": got[1], "lat_ns": lat[:min(got[0], expect)].tolist(),
             "foreign": sub.counts.foreign + sub.counts.corrupt})
    sub.close()
    session.close()


def _run(n_subs: int, frames: int, rate_hz: float | None) -> dict[str, Any]:
    endpoint = free_loopback_endpoint()
    session = open_session(listen=[endpoint])
    bus = Bus(history=1000)
    pub = RemotePublisher(session, bus, _RIG, prefixes=(_TOPIC,))
    ctx = mp.get_context("spawn")
    out = ctx.Queue()
    readies = [ctx.Event() for _ in range(n_subs)]
    procs = [ctx.Process(target=_subscriber, args=(endpoint, frames, r, out), daemon=True) for r in readies]
    for p in procs:
        p.start()
    try:
        for r in readies:
            if not r.wait(30.0):
                raise RuntimeError("a subscriber process did not start")
        time.sleep(0.5)  # their sessions meet ours
        w = np.zeros(6)
        w.flags.writeable = False
        publish, period, clock = bus.publish, (1e9 / rate_hz if rate_hz else 0.0), time.monotonic_ns
        t0 = clock()
        for i in range(frames):
            if period:  # slept, not spun: a spinning publisher would take a core from Zenoh's threads
                ahead = (t0 + i * period - clock()) / 1e9
                if ahead > 0:
                    time.sleep(ahead)
            publish(_TOPIC, WrenchFrame(clock(), None, i, "bench", w))
        results = [out.get(timeout=150.0) for _ in procs]
    finally:
        for p in procs:
            p.join(5.0)
            if p.is_alive():
                p.kill()
        pub.close()
        session.close()
    lat = np.concatenate([np.asarray(r["lat_ns"], dtype=float) for r in results]) / 1e3
    slowest = max(r["t_last_ns"] for r in results)
    return {"subscribers": n_subs, "frames": frames, "received_min": min(r["received"] for r in results),
            "frames_per_s": frames / max((slowest - t0) / 1e9, 1e-9),
            "latency_us": _latency_us(lat)}


def _latency_us(lat: np.ndarray) -> dict[str, float]:
    """Median, p99 and max of latencies in us ({} for none)."""
    if not len(lat):
        return {}
    return {"median": float(np.median(lat)), "p99": float(np.percentile(lat, 99)), "max": float(lat.max())}


def _raw_subscriber(endpoint: str, expect: int, ready: Any, out: Any) -> None:
    """Zenoh alone: each message's put time (its first 8 bytes) to its arrival in a Python callback."""
    session = open_session(connect=[endpoint])
    lat: list[int] = []

    def on_sample(sample: Any) -> None:
        lat.append(time.monotonic_ns() - struct.unpack_from("<q", sample.payload.to_bytes())[0])

    sub = session.declare_subscriber(_RAW_KEY, on_sample)
    ready.set()
    end = time.monotonic() + 120.0
    while len(lat) < expect and time.monotonic() < end:
        time.sleep(0.01)
    out.put(lat[:expect])
    with contextlib.suppress(zenoh.ZError):
        sub.undeclare()
    session.close()


def _raw(messages: int, gaps_s: tuple[float, float], express: bool) -> dict[str, Any]:
    """Zenoh's own put-to-callback latency between two processes, ``messages`` paced by ``gaps_s``."""
    endpoint = free_loopback_endpoint()
    session = open_session(listen=[endpoint])
    pub = session.declare_publisher(_RAW_KEY, congestion_control=zenoh.CongestionControl.BLOCK,
                                    reliability=zenoh.Reliability.RELIABLE, express=express)
    ctx = mp.get_context("spawn")
    out, ready = ctx.Queue(), ctx.Event()
    proc = ctx.Process(target=_raw_subscriber, args=(endpoint, messages, ready, out), daemon=True)
    proc.start()
    try:
        if not ready.wait(30.0):
            raise RuntimeError("the raw subscriber process did not start")
        time.sleep(0.5)
        pad = bytes(len(encode(WrenchFrame(0, 0, 0, "bench", np.zeros(6)))) - 8)
        rng, due = random.Random(0), time.monotonic()
        for _ in range(messages):
            time.sleep(max(due - time.monotonic(), 0.0))  # paced as the latency run: late ones catch up
            due += rng.uniform(*gaps_s)
            pub.put(struct.pack("<q", time.monotonic_ns()) + pad)
        lat = np.asarray(out.get(timeout=150.0), dtype=float) / 1e3
    finally:
        proc.join(5.0)
        if proc.is_alive():
            proc.kill()
        pub.undeclare()
        session.close()
    return {"messages": messages, "received": len(lat), "latency_us": _latency_us(lat)}


def measure(frames: int = 100_000, latency_frames: int = 5_000, rate_hz: float = 1000.0) -> dict[str, Any]:
    """Throughput and latency with 1 and 4 subscriber processes; Zenoh's own floor beside them."""
    result: dict[str, Any] = {
        f"{n}_sub": {"throughput": _run(n, frames, None), "latency": _run(n, latency_frames, rate_hz)}
        for n in (1, 4)}
    result["raw"] = {"paced": _raw(latency_frames, (1.0 / rate_hz, 1.0 / rate_hz), express=False),
                     "sporadic": _raw(200, (0.02, 0.06), express=True)}
    return result
