"""An MCAP bag read record by record from its start, for a file rosbags cannot open: a recorder killed
before it wrote the summary and footer leaves exactly that, often inside a chunk. The ``mcap`` library's
stream reader stops at a cut chunk, losing every message in it; here an uncompressed chunk is read up to
its last whole record. The break is raised after the last good message, so the reader marks the bag cut
short.

The records used (MCAP spec, little-endian; ``str`` = u32 length + UTF-8, ``bytes`` = u32 length + data)::

    record   : opcode u8 | length u64 | body (length bytes)
    0x03 Schema  : id u16 | name str | encoding str | data bytes
    0x04 Channel : id u16 | schema_id u16 | topic str | message_encoding str | metadata (u32 length + map)
    0x05 Message : channel_id u16 | sequence u32 | log_time u64 | publish_time u64 | data (the rest)
    0x06 Chunk   : start u64 | end u64 | uncompressed_size u64 | uncompressed_crc u32 | compression str
                   | records_length u64 | records (records_length bytes, compressed as said)
"""
from __future__ import annotations

import struct
from collections import Counter
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

MAGIC = b"\x89MCAP0\r\n"
SCHEMA, CHANNEL, MESSAGE, CHUNK = 0x03, 0x04, 0x05, 0x06


class CutShort(Exception):
    """The file ends inside a record (or a compressed chunk is cut: nothing of it can be read)."""


@dataclass(frozen=True)
class StreamConnection:
    """A channel as rosbags names a connection's fields: ``id``, ``topic``, ``msgtype``, ``msgcount``."""

    id: int
    topic: str
    msgtype: str
    msgcount: int


def _str(body: bytes, at: int) -> tuple[str, int]:
    (n,) = struct.unpack_from("<I", body, at)
    return body[at + 4:at + 4 + n].decode("utf-8"), at + 4 + n


def _records(data: bytes, at: int) -> Iterator[tuple[int, bytes]]:
    """``(opcode, body)`` of the records from ``at``; chunks opened; :class:`CutShort` where data ends."""
    while at < len(data):
        if at + 9 > len(data):
            raise CutShort(f"the file ends inside a record's header at byte {at}")
        op, n = data[at], struct.unpack_from("<Q", data, at + 1)[0]
        body = data[at + 9:at + 9 + n]
        cut = len(body) < n
        if op == CHUNK:
            yield from _chunk(body, cut, at)
        elif cut:
            raise CutShort(f"the file ends inside a record (opcode {op:#04x}) at byte {at}")
        else:
            yield op, body
        at += 9 + n


def _chunk(body: bytes, cut: bool, at: int) -> Iterator[tuple[int, bytes]]:
    if len(body) < 28:
        raise CutShort(f"the file ends inside a chunk's header at byte {at}")
    compression, i = _str(body, 28)
    records = body[i + 8:i + 8 + struct.unpack_from("<Q", body, i)[0]]
    if compression and cut:
        raise CutShort(f"the file ends inside a {compression}-compressed chunk at byte {at}: its messages are lost")
    if compression == "zstd":
        import zstandard  # lazy: only a compressed chunk needs it (a dependency of rosbags)
        size = struct.unpack_from("<Q", body, 16)[0]
        records = zstandard.ZstdDecompressor().decompress(records, max_output_size=size)
    elif compression == "lz4":
        import lz4.frame  # lazy: only a compressed chunk needs it (a dependency of rosbags)
        records = lz4.frame.decompress(records)
    yield from _records(records, 0)
    if cut:
        raise CutShort(f"the file ends inside a chunk at byte {at}")


def read_records(path: Path) -> Iterator[tuple[int, bytes]]:
    """Every whole record of the MCAP file at ``path`` in file order, chunks opened; then :class:`CutShort`."""
    data = path.read_bytes()
    if not data.startswith(MAGIC):
        raise CutShort(f"{path} does not start with MCAP's magic")
    yield from _records(data, len(MAGIC))


class McapStreamBag:
    """The part of ``rosbags.rosbag2.Reader`` that :mod:`.bag_read` uses, over a bare MCAP file read from
    its start (ros2 profile: schema names are ROS message types, data is CDR)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.connections: list[StreamConnection] = []
        self.break_: CutShort | None = None  # where the file breaks off (None: no break found)

    def open(self) -> None:
        schemas: dict[int, str] = {}
        channels: dict[int, tuple[str, int]] = {}
        counts: Counter[int] = Counter()
        try:
            for op, body in read_records(self.path):
                if op == SCHEMA:
                    schemas[struct.unpack_from("<H", body)[0]] = _str(body, 2)[0]
                elif op == CHANNEL:
                    cid, sid = struct.unpack_from("<HH", body)
                    channels[cid] = (_str(body, 4)[0], sid)
                elif op == MESSAGE:
                    counts[struct.unpack_from("<H", body)[0]] += 1
        except CutShort as exc:
            self.break_ = exc
        self.connections = [StreamConnection(cid, topic, schemas.get(sid, ""), counts[cid])
                            for cid, (topic, sid) in sorted(channels.items())]

    def close(self) -> None:
        pass

    def messages(self, connections: Iterable[StreamConnection]) -> Iterator[tuple[StreamConnection, int, bytes]]:
        """``(connection, log time ns, CDR bytes)`` of those connections in file order; then the break, if any."""
        wanted = {c.id: c for c in connections}
        try:
            for op, body in read_records(self.path):
                if op == MESSAGE and (conn := wanted.get(struct.unpack_from("<H", body)[0])) is not None:
                    yield conn, struct.unpack_from("<Q", body, 6)[0], body[22:]
        except CutShort:
            pass
        if self.break_ is not None:
            raise self.break_
