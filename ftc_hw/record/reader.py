"""Reads an ``ftc`` MCAP recording record by record, so that a file cut short (a killed recorder)
reads up to its last complete chunk: ``Recording.complete`` is False and ``error`` says where it ended.
The Foxglove channels (``foxglove.*`` schemas: a view of the bus, made from its frames) are skipped,
counted in ``Recording.view_messages``.
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.exceptions import McapError
from mcap.records import Channel, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from .schemas import decode

VIEW_SCHEMAS = "foxglove."


class RecordingError(Exception):
    """Not an MCAP file, or nothing readable in it."""


@dataclass(frozen=True, slots=True)
class RecordedMessage:
    topic: str
    log_time: int  # host monotonic ns
    publish_time: int  # device time, ns (host time when the device sends none)
    frame: Any


@dataclass
class Recording:
    path: Path
    messages: list[RecordedMessage] = field(default_factory=list)  # in file order (= publish order)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    complete: bool = False  # the footer was read
    error: str | None = None  # why reading stopped early
    bad_messages: int = 0
    view_messages: int = 0  # messages in Foxglove's schemas, not read (no bus frame in them)

    def topic(self, name: str) -> list[Any]:
        return [m.frame for m in self.messages if m.topic == name]

    def counts(self) -> Counter[str]:
        return Counter(m.topic for m in self.messages)


def read_recording(path: Path | str, topics: set[str] | None = None) -> Recording:
    rec = Recording(Path(path))
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, str]] = {}
    try:
        with open(path, "rb") as f:
            for record in StreamReader(f, validate_crcs=True).records:
                if isinstance(record, Schema):
                    schemas[record.id] = record.name
                elif isinstance(record, Channel):
                    channels[record.id] = (record.topic, schemas.get(record.schema_id, ""))
                elif isinstance(record, Message):
                    topic, schema = channels[record.channel_id]
                    if topics is not None and topic not in topics:
                        continue
                    if schema.startswith(VIEW_SCHEMAS):
                        rec.view_messages += 1
                        continue
                    try:
                        frame = decode(schema, record.data)
                    except (ValueError, KeyError, TypeError):
                        rec.bad_messages += 1
                        continue
                    rec.messages.append(RecordedMessage(topic, record.log_time, record.publish_time, frame))
                elif isinstance(record, Metadata):
                    rec.metadata[record.name] = dict(record.metadata)
                elif isinstance(record, Footer):
                    rec.complete = True
    except (McapError, EOFError, ValueError, KeyError) as exc:
        if not rec.messages and not rec.metadata:
            raise RecordingError(f"{path}: not a readable MCAP recording ({type(exc).__name__}: {exc})") from None
        rec.error = f"{type(exc).__name__}: {exc}"
    return rec
