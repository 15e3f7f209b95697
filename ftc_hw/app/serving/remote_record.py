"""``ftc record --remote ENDPOINT``: a recorder in its own process, on the frames ``ftc serve`` (and a
remote monitor's events) publish on Zenoh: every ``ftc/<rig>/...`` topic into an MCAP file, as ``ftc
monitor --record`` writes them. A monitor that dies takes nothing of this recording with it; what the
recorder could not have (frames missing by their sequence numbers, payloads that were not ours) the
summary says."""
from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ftc_hw.bus import Bus
from ftc_hw.bus.remote import RemoteSubscriber, connect_session
from ftc_hw.record.writer import McapRecorder


@dataclass
class RecordOutcome:
    counts: dict[str, int] = field(default_factory=dict)  # messages written per topic
    seq_missing: dict[str, int] = field(default_factory=dict)  # per sensor topic, by sequence number
    remote: dict[str, Any] = field(default_factory=dict)
    drops: int = 0  # frames the writer could not keep up with


def record_remote(endpoint: str, rig: str, out: Path, duration: float | None = None,
                  zenoh_config: Path | None = None, say: Callable[[str], None] = print,
                  connect_timeout: float = 20.0) -> RecordOutcome:
    """Record until ``duration`` seconds are up, or SIGINT/SIGTERM; RemoteError if nothing serves there."""
    session = connect_session(endpoint, connect_timeout, config_file=zenoh_config)
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    bus = Bus(history=1000)
    meta = {"remote": {"endpoint": endpoint, "rig": rig, "started_host_ns": str(time.monotonic_ns())}}
    recorder = McapRecorder(bus, out, metadata=meta).start()
    sub = RemoteSubscriber(session, bus, rig)
    say(f"recording ftc/{rig}/... from {endpoint} -> {out}")
    try:
        stop.wait(duration)
    finally:
        sub.close()
        recorder.stop()
        session.close()
    result = RecordOutcome(dict(recorder.counts), drops=recorder.drops, remote=sub.counts.summary())
    result.seq_missing = {t: bus.stats(t).seq_missing for t in bus.topics() if t.startswith(("wrench/", "joints/"))}
    say(f"recorded {sum(result.counts.values())} messages ({', '.join(f'{t} {n}' for t, n in result.counts.items())}); "
        f"missing by sequence number: {result.seq_missing}; from Zenoh: {result.remote}; writer drops {result.drops}")
    return result
