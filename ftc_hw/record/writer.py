"""Records a bus to MCAP: one channel per bus topic (JSON messages with a JSON Schema), ``log_time`` =
the frame's host ``time.monotonic_ns()``, ``publish_time`` = its device time (the host time when the
device sends none), metadata for the scene, calibration and monitor settings (at the start) and the
contact events (at the end).

Crash-safe: the chunk in progress is closed and flushed to the OS every ``flush_s`` seconds (and
whenever it reaches ``chunk_size``), so a recorder that is killed leaves a file that reads up to its
last complete chunk (:func:`ftc_hw.record.reader.read_recording` reads such a file).

A queue subscription decouples the publishers (device reader threads) from the encoding: the
recorder's thread drains it every ``poll_s``; a full queue drops the oldest frames, counted in
``drops`` and written to the final metadata.
"""
from __future__ import annotations

import json
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Any

from mcap.writer import CompressionType, Writer

from ftc_hw import __version__
from ftc_hw.bus import Bus

from .schemas import SCHEMAS, encode, topic_of

PROFILE = ""  # no well-known MCAP profile (not ROS); the schemas say what the messages are
LIBRARY = f"ftc-hw/{__version__}"


class McapRecorder:
    """``with McapRecorder(bus, "run.mcap", metadata={...}):`` records every topic under ``prefix``."""

    def __init__(self, bus: Bus, path: Path | str, *, metadata: dict[str, dict[str, str]] | None = None,
                 prefix: str = "", chunk_size: int = 256 * 1024, flush_s: float = 0.2,
                 maxsize: int = 200_000, poll_s: float = 0.02) -> None:
        self.bus = bus
        self.path = Path(path)
        self.metadata = dict(metadata or {})
        self.prefix = prefix
        self.chunk_size = chunk_size
        self.flush_s = flush_s
        self.maxsize = maxsize
        self.poll_s = poll_s
        self.counts: Counter[str] = Counter()
        self.skipped = 0  # frames of a type with no schema
        self.drops = 0
        self._lock = threading.Lock()
        self._file: Any = None
        self._writer: Writer | None = None
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._sub = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()

    def start(self) -> McapRecorder:
        if self._writer is not None:
            return self
        self._file = open(self.path, "wb")  # noqa: SIM115 - closed in stop()
        self._writer = Writer(self._file, chunk_size=self.chunk_size, compression=CompressionType.ZSTD)
        self._writer.start(profile=PROFILE, library=LIBRARY)
        for name, data in self.metadata.items():
            self._writer.add_metadata(name, data)
        self._writer.flush()
        self._sub = self.bus.subscribe(self.prefix, maxsize=self.maxsize, prefix=True)
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="mcap-recorder", daemon=True)
        self._thread.start()
        return self

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        with self._lock:
            if self._writer is not None:
                self._writer.add_metadata(name, {k: str(v) for k, v in data.items()})
                self._file.flush()

    def _channel(self, topic: str, schema: str) -> int:
        cid = self._channels.get(topic)
        if cid is None:
            sid = self._schemas.get(schema)
            if sid is None:
                sid = self._writer.register_schema(schema, "jsonschema", json.dumps(SCHEMAS[schema]).encode())
                self._schemas[schema] = sid
            cid = self._writer.register_channel(topic, "json", sid)
            self._channels[topic] = cid
        return cid

    def write(self, frame: Any) -> None:
        """Write one frame (the recorder's thread does this for every frame on the bus)."""
        topic = topic_of(frame)
        if topic is None:
            self.skipped += 1
            return
        schema, data = encode(frame)
        t_dev = getattr(frame, "t_device_ns", None)
        with self._lock:
            cid = self._channel(topic, schema)
            self._writer.add_message(cid, log_time=frame.t_host_ns, data=data,
                                     publish_time=frame.t_host_ns if t_dev is None else t_dev,
                                     sequence=int(getattr(frame, "seq", self.counts[topic])) & 0xFFFFFFFF)
        self.counts[topic] += 1

    def _run(self) -> None:
        # Polls instead of waiting on the subscription: a waiting consumer makes every publish wake
        # it, and those thousands of wake-ups a second took the interpreter from the device readers
        # (a 1 kHz CAN reader fell behind and lost frames). A batch every poll_s costs the same encoding.
        last_flush = time.monotonic()
        while not self._sub.closed:
            for f in self._sub.drain():
                self.write(f)
            if time.monotonic() - last_flush >= self.flush_s:
                with self._lock:
                    self._writer.flush()  # closes the chunk and flushes the file
                last_flush = time.monotonic()
            self._stop.wait(self.poll_s)

    def stop(self, final_metadata: dict[str, dict[str, str]] | None = None) -> None:
        """Write what is queued, then ``final_metadata`` and the summary; close the file."""
        if self._writer is None:
            return
        self._sub.close()
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=30.0)
            self._thread = None
        for f in self._sub.drain():
            self.write(f)
        self.drops = self._sub.drops
        with self._lock:
            meta = {"recorder": {"drops": str(self.drops), "skipped": str(self.skipped),
                                 **{f"messages:{k}": str(v) for k, v in sorted(self.counts.items())}}}
            for name, data in {**meta, **(final_metadata or {})}.items():
                self._writer.add_metadata(name, {k: str(v) for k, v in data.items()})
            self._writer.finish()
            self._file.close()
            self._writer = None

    def __enter__(self) -> McapRecorder:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
