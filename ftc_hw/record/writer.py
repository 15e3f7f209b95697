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

Given the ``scene``, the recorder also writes the scene in Foxglove's well-known schemas beside those
channels (:mod:`.foxglove_view`): the bus's channels are the same bytes with or without it.
"""
from __future__ import annotations

import json
import threading
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

from mcap.writer import CompressionType, Writer

from ftc_hw import __version__
from ftc_hw.bus import Bus
from ftc_hw.scene import Scene

from .foxglove_messages import foxglove_schema
from .foxglove_view import FoxgloveMessage, FoxgloveView
from .schemas import SCHEMAS, encode, topic_of

PROFILE = ""  # no well-known MCAP profile (not ROS); the schemas say what the messages are
LIBRARY = f"ftc-hw/{__version__}"


def end_polling(sub: Any, stop: threading.Event, thread: threading.Thread | None) -> None:
    """Close a recorder's subscription and wait for its polling thread to end (the caller then drains
    what is left)."""
    sub.close()
    stop.set()
    if thread is not None:
        thread.join(timeout=30.0)


class McapRecorder:
    """``with McapRecorder(bus, "run.mcap", metadata={...}):`` records every topic under ``prefix``;
    with ``scene``, the Foxglove channels too."""

    def __init__(self, bus: Bus, path: Path | str, *, metadata: dict[str, dict[str, str]] | None = None,
                 prefix: str = "", chunk_size: int = 256 * 1024, flush_s: float = 0.2,
                 maxsize: int = 200_000, poll_s: float = 0.02, scene: Scene | None = None) -> None:
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
        self.cpu_s = 0.0  # the recorder thread's CPU time (and the final drain's)
        self.foxglove = FoxgloveView(scene) if scene is not None else None
        self.foxglove_errors = 0  # frames whose Foxglove messages failed (the first error in the metadata)
        self.foxglove_error = ""
        self._fox_seq: dict[str, int] = {}
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
        self.open()
        self._sub = self.bus.subscribe(self.prefix, maxsize=self.maxsize, prefix=True)
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="mcap-recorder", daemon=True)
        self._thread.start()
        return self

    def open(self) -> None:
        """The file, its header and start metadata (``start`` then records the bus; a writer fed another
        way, :mod:`.writer_process`, calls ``write``, ``flush`` and ``finish`` itself)."""
        self._file = open(self.path, "wb")  # noqa: SIM115 - closed in finish()
        self._writer = Writer(self._file, chunk_size=self.chunk_size, compression=CompressionType.ZSTD)
        self._writer.start(profile=PROFILE, library=LIBRARY)
        for name, data in self.metadata.items():
            self._writer.add_metadata(name, data)
        if self.foxglove is not None:
            self._writer.add_metadata("foxglove", self.foxglove.describe())
            self._feed_foxglove(self.foxglove.start, time.monotonic_ns())
        self._writer.flush()

    def flush(self) -> None:
        """Close the chunk in progress and flush the file (what a killed recorder leaves readable)."""
        with self._lock:
            self._writer.flush()

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
                body = SCHEMAS[schema] if schema in SCHEMAS else foxglove_schema(schema)
                sid = self._writer.register_schema(schema, "jsonschema", json.dumps(body).encode())
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
        if self.foxglove is not None:
            self._feed_foxglove(self.foxglove.feed, frame)

    def _feed_foxglove(self, make: Callable[[Any], list[FoxgloveMessage]], arg: Any) -> None:
        try:
            for m in make(arg):
                self._write_foxglove(m)
        except Exception as exc:  # noqa: BLE001 - a view: nothing in it may cost the bus's channels
            self.foxglove_errors += 1
            self.foxglove_error = self.foxglove_error or f"{type(exc).__name__}: {exc}"

    def _write_foxglove(self, m: FoxgloveMessage) -> None:
        data = json.dumps(m.data, separators=(",", ":"), allow_nan=False).encode()
        seq = self._fox_seq.get(m.topic, 0)
        self._fox_seq[m.topic] = seq + 1
        with self._lock:
            self._writer.add_message(self._channel(m.topic, m.schema), log_time=m.log_time, data=data,
                                     publish_time=m.log_time, sequence=seq & 0xFFFFFFFF)

    def _run(self) -> None:
        # Polls instead of waiting on the subscription: a waiting consumer makes every publish wake
        # it, and those thousands of wake-ups a second took the interpreter from the device readers
        # (a 1 kHz CAN reader fell behind and lost frames). A batch every poll_s costs the same encoding.
        cpu0 = time.thread_time()
        last_flush = time.monotonic()
        while not self._sub.closed:
            for f in self._sub.drain():
                self.write(f)
            if time.monotonic() - last_flush >= self.flush_s:
                self.flush()
                last_flush = time.monotonic()
            self._stop.wait(self.poll_s)
        self.cpu_s += time.thread_time() - cpu0

    def stop(self, final_metadata: dict[str, dict[str, str]] | None = None) -> None:
        """Write what is queued, then ``final_metadata`` and the summary; close the file."""
        if self._writer is None:
            return
        end_polling(self._sub, self._stop, self._thread)
        self._thread = None
        cpu0 = time.thread_time()
        for f in self._sub.drain():
            self.write(f)
        self.cpu_s += time.thread_time() - cpu0
        self.drops = self._sub.drops
        self.finish(final_metadata)

    def finish(self, final_metadata: dict[str, dict[str, str]] | None = None) -> None:
        """The summary (drops, counts, CPU) and ``final_metadata``; the file closed."""
        with self._lock:
            meta = {"recorder": {"drops": str(self.drops), "skipped": str(self.skipped), "cpu_s": f"{self.cpu_s:.3f}",
                                 **{f"messages:{k}": str(v) for k, v in sorted(self.counts.items())},
                                 **self._foxglove_summary()}}
            for name, data in {**meta, **(final_metadata or {})}.items():
                self._writer.add_metadata(name, {k: str(v) for k, v in data.items()})
            self._writer.finish()
            self._file.close()
            self._writer = None

    def _foxglove_summary(self) -> dict[str, str]:
        if self.foxglove is None:
            return {}
        out = {f"messages:{k}": str(v) for k, v in sorted(self.foxglove.counts.items())}
        out.update({f"foxglove_skipped:{k}": str(v) for k, v in sorted(self.foxglove.skipped.items())})
        out["foxglove_errors"] = str(self.foxglove_errors)
        if self.foxglove_error:
            out["foxglove_error"] = self.foxglove_error
        return out

    def __enter__(self) -> McapRecorder:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
