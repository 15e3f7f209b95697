"""Fixed-size binary stream frames described as data, and a resynchronising parser.

A :class:`StreamFormat` is a table: header bytes, typed fields in order, a checksum and which bytes it
covers. Field names with a meaning: ``fx fy fz tx ty tz`` (required; ``scale`` = SI units per count),
``seq`` (sample counter, wraps at the field's width), ``t_device`` (device clock; ``scale`` = ns per
count, wraps), ``status`` (bit i set = axis i saturated, bit 7 = device error). Any other name is
carried but ignored. Two formats ship:

``ft300`` (Robotiq FT 300 data stream, 100 Hz, 16 bytes; Robotiq's ``rq_sensor_com.c``)::

    20 4E | fx fy fz tx ty tz: int16 LE (F / 100 -> N, M / 1000 -> N m) | CRC-16/MODBUS LE over bytes 0-13

``ftc-1k`` (this project's 1 kHz stream, 35 bytes, little-endian)::

    offset size field
     0     2    sync A5 5A
     2     2    seq       uint16  +1 per sample, wraps at 65536
     4     4    t_device  uint32  device clock in microseconds, wraps after 71.6 min
     8    24    fx..tz    int32   forces 1e-4 N per count, torques 1e-5 N m per count
    32     1    status    uint8   bit i = axis i saturated (0..5: fx..tz), bit 7 = device error
    33     2    crc       CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) over bytes 2-32, LE

:meth:`StreamFormat.decode` does no I/O: bytes in, ``(consumed, sample or None)`` out, or a typed
:class:`~ftc_hw.codecs.errors.CodecError` whose ``consumed`` says how far to skip.
"""
from __future__ import annotations

import math
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from .checksums import CHECKSUMS
from .errors import ChecksumError, CodecError, FrameFormatError

AXES = ("fx", "fy", "fz", "tx", "ty", "tz")
STATUS_ERROR = 0x80

# name -> (struct code, is_float)
FIELD_TYPES: dict[str, tuple[str, bool]] = {
    "u8": ("B", False), "i8": ("b", False), "u16": ("H", False), "i16": ("h", False),
    "u32": ("I", False), "i32": ("i", False), "u64": ("Q", False), "i64": ("q", False),
    "f32": ("f", True), "f64": ("d", True),
}


@dataclass(frozen=True)
class StreamField:
    name: str
    type: str
    scale: float = 1.0

    @property
    def bits(self) -> int:
        return 8 * struct.calcsize(FIELD_TYPES[self.type][0])

    @property
    def is_float(self) -> bool:
        return FIELD_TYPES[self.type][1]


@dataclass(frozen=True)
class StreamSample:
    """One decoded frame: ``wrench`` in SI; ``seq`` and ``t_device_ns`` as sent (still wrapped)."""

    wrench: tuple[float, ...]
    seq: int | None = None
    t_device_ns: int | None = None
    status: int | None = None


@dataclass(frozen=True)
class StreamFormat:
    name: str
    header: bytes
    fields: tuple[StreamField, ...]
    checksum: str = "none"
    checksum_from: int = 0  # first byte the checksum covers (0: the header too)
    byte_order: str = "little"
    rate_hz: float | None = None
    range: tuple[float, ...] | None = None  # device full scale (SI): saturation when there is no status
    description: str = ""
    _struct: struct.Struct = field(init=False, repr=False, compare=False)
    _index: dict[str, int] = field(init=False, repr=False, compare=False)
    _axes: tuple[int, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not self.header:
            raise ValueError(f"{self.name}: the header must not be empty")
        names = [f.name for f in self.fields]
        if sorted(n for n in names if n in AXES) != sorted(AXES) or len(set(names)) != len(names):
            raise ValueError(f"{self.name}: fields must hold each of {AXES} once, no duplicate names")
        for f in self.fields:
            if f.type not in FIELD_TYPES:
                raise ValueError(f"{self.name}: field {f.name}: unknown type {f.type!r} ({', '.join(FIELD_TYPES)})")
            if not f.scale or not math.isfinite(f.scale):
                raise ValueError(f"{self.name}: field {f.name}: scale must be finite and non-zero")
            if f.name in ("seq", "t_device", "status") and f.is_float:
                raise ValueError(f"{self.name}: field {f.name} must be an integer type")
        if self.checksum != "none" and self.checksum not in CHECKSUMS:
            raise ValueError(f"{self.name}: unknown checksum {self.checksum!r} ({', '.join(CHECKSUMS)}, none)")
        if self.byte_order not in ("little", "big"):
            raise ValueError(f"{self.name}: byte_order must be 'little' or 'big'")
        if self.range is not None and len(self.range) != 6:
            raise ValueError(f"{self.name}: range must have 6 values")
        prefix = "<" if self.byte_order == "little" else ">"
        body = struct.Struct(prefix + "".join(FIELD_TYPES[f.type][0] for f in self.fields))
        object.__setattr__(self, "_struct", body)
        index = {f.name: i for i, f in enumerate(self.fields)}
        object.__setattr__(self, "_index", index)
        object.__setattr__(self, "_axes", tuple(index[a] for a in AXES))
        if not 0 <= self.checksum_from <= len(self.header) + body.size:
            raise ValueError(f"{self.name}: checksum_from out of the frame")

    # -- geometry ------------------------------------------------------------------------------------
    @property
    def checksum_size(self) -> int:
        return 0 if self.checksum == "none" else CHECKSUMS[self.checksum].size

    @property
    def size(self) -> int:
        return len(self.header) + self._struct.size + self.checksum_size

    def field(self, name: str) -> StreamField | None:
        i = self._index.get(name)
        return None if i is None else self.fields[i]

    @property
    def seq_modulus(self) -> int | None:
        f = self.field("seq")
        return None if f is None else 1 << f.bits

    @property
    def t_device_modulus_ns(self) -> int | None:
        f = self.field("t_device")
        return None if f is None else round((1 << f.bits) * f.scale)

    @property
    def has_status(self) -> bool:
        return "status" in self._index

    # -- encode (emulators, tests) -------------------------------------------------------------------
    def encode(self, wrench: Sequence[float], *, seq: int = 0, t_device_ns: int = 0, status: int = 0,
               extra: Mapping[str, float] | None = None) -> bytes:
        """The frame of one sample. Values are rounded to the field's resolution and clipped to its type."""
        values: list[Any] = []
        for f in self.fields:
            if f.name in AXES:
                v = float(wrench[AXES.index(f.name)]) / f.scale
            elif f.name == "seq":
                v = seq
            elif f.name == "t_device":
                v = round(t_device_ns / f.scale)
            elif f.name == "status":
                v = status
            else:
                v = (extra or {}).get(f.name, 0)
            values.append(v if f.is_float else _wrap_or_clip(f, v))
        body = self.header + self._struct.pack(*values)
        if self.checksum != "none":
            c = CHECKSUMS[self.checksum]
            crc = c.func(body[self.checksum_from:])
            body += crc.to_bytes(c.size, self.byte_order)
        return body

    # -- decode --------------------------------------------------------------------------------------
    def decode(self, buffer: bytes | bytearray | memoryview) -> tuple[int, StreamSample | None]:
        """Decode the frame at the start of ``buffer``.

        Returns ``(n, sample)`` for a frame of ``n`` bytes; ``(n, None)`` with ``n > 0``: skip ``n``
        bytes of garbage before the next possible header; ``(0, None)``: need more bytes. Raises
        :class:`ChecksumError` / :class:`FrameFormatError` (skip ``exc.consumed`` bytes).
        """
        buf = buffer if isinstance(buffer, bytes) else bytes(buffer)
        h = self.header
        i = buf.find(h)
        if i < 0:
            return len(buf) - _header_prefix_suffix(buf, h), None
        if i > 0:
            return i, None
        size = self.size
        if len(buf) < size:
            return 0, None
        if self.checksum != "none":
            c = CHECKSUMS[self.checksum]
            want = int.from_bytes(buf[size - c.size:size], self.byte_order)
            if c.func(buf[self.checksum_from:size - c.size]) != want:
                # A bad frame followed by an aligned header was one whole frame (skip it at once);
                # otherwise skip one byte so that a frame starting inside this one is found.
                if len(buf) < size + len(h):
                    return 0, None
                skip = size if buf[size:size + len(h)] == h else 1
                raise ChecksumError(f"{self.name}: checksum mismatch", consumed=skip)
        values = self._struct.unpack_from(buf, len(h))
        fields = self.fields
        w = tuple(values[i] * fields[i].scale for i in self._axes)
        if not all(map(math.isfinite, w)):
            raise FrameFormatError(f"{self.name}: non-finite value in {w}", consumed=size)
        idx = self._index
        seq = values[idx["seq"]] if "seq" in idx else None
        t_dev = round(values[idx["t_device"]] * self.fields[idx["t_device"]].scale) if "t_device" in idx else None
        status = values[idx["status"]] if "status" in idx else None
        return size, StreamSample(w, seq, t_dev, status)

    # -- data ------------------------------------------------------------------------------------------
    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> StreamFormat:
        """From a scene table: ``{name, header (hex string), fields: [{name, type, scale}], checksum,
        checksum_from, byte_order, rate_hz, range}``."""
        try:
            fields = tuple(StreamField(str(f["name"]), str(f["type"]), float(f.get("scale", 1.0)))
                           for f in d["fields"])
            header = bytes.fromhex(str(d["header"]))
            rng = d.get("range")
            return cls(name=str(d.get("name", "custom")), header=header, fields=fields,
                       checksum=str(d.get("checksum", "none")), checksum_from=int(d.get("checksum_from", 0)),
                       byte_order=str(d.get("byte_order", "little")),
                       rate_hz=None if d.get("rate_hz") is None else float(d["rate_hz"]),
                       range=None if rng is None else tuple(float(x) for x in rng))
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"stream format table: {exc}") from None


def _wrap_or_clip(f: StreamField, v: float) -> int:
    code = FIELD_TYPES[f.type][0]
    bits = f.bits
    n = round(v)
    if f.name in ("seq", "t_device"):
        return n % (1 << bits)  # counters wrap
    if code.isupper():
        return min(max(n, 0), (1 << bits) - 1)
    lim = 1 << (bits - 1)
    return min(max(n, -lim), lim - 1)


def _header_prefix_suffix(buf: bytes, h: bytes) -> int:
    """Length of the longest suffix of ``buf`` that is a proper prefix of ``h`` (a header cut in two)."""
    for k in range(min(len(h) - 1, len(buf)), 0, -1):
        if buf.endswith(h[:k]):
            return k
    return 0


class StreamParser:
    """Feeds bytes through a format; returns whole valid frames; counts what it threw away.

    Counters (one per *bad region*, i.e. everything between two valid frames that was not a frame):
    ``checksum_errors`` (the region held a candidate with a bad checksum), ``format_errors`` (a
    candidate with impossible contents), ``resyncs`` (only garbage). ``bytes_discarded`` counts bytes.
    Garbage before the first frame after :meth:`reset` (joining a stream mid-frame) counts as ``sync_bytes``.
    """

    def __init__(self, fmt: StreamFormat, max_buffer: int = 1 << 16) -> None:
        self.fmt = fmt
        self.max_buffer = max_buffer
        self.frames = self.checksum_errors = self.format_errors = self.resyncs = 0
        self.bytes_discarded = self.sync_bytes = 0
        self._buf = bytearray()
        self._synced = False
        self._bad: set[str] = set()
        self._bad_bytes = 0

    def reset(self) -> None:
        self._buf.clear()
        self._close_region()
        self._synced = False

    @property
    def pending(self) -> int:
        return len(self._buf)

    def counters(self) -> dict[str, int]:
        return {"frames": self.frames, "checksum_errors": self.checksum_errors, "format_errors": self.format_errors,
                "resyncs": self.resyncs, "bytes_discarded": self.bytes_discarded, "sync_bytes": self.sync_bytes}

    def feed(self, data: bytes) -> list[StreamSample]:
        buf = self._buf
        buf += data
        out: list[StreamSample] = []
        pos = 0
        while pos < len(buf):
            try:
                n, sample = self.fmt.decode(bytes(buf[pos:]))
            except CodecError as exc:
                self._bad.add("checksum" if isinstance(exc, ChecksumError) else "format")
                self._discard(exc.consumed)
                pos += exc.consumed
                continue
            if n == 0:
                break
            pos += n
            if sample is None:
                self._bad.add("garbage")
                self._discard(n)
                continue
            self._close_region()
            self._synced = True
            self.frames += 1
            out.append(sample)
        del buf[:pos]
        if len(buf) > self.max_buffer:  # a stuck candidate can only be garbage this far behind
            drop = len(buf) - self.max_buffer
            self._bad.add("garbage")
            self._discard(drop)
            del buf[:drop]
        return out

    def _discard(self, n: int) -> None:
        self._bad_bytes += n

    def _close_region(self) -> None:
        if self._bad:
            if not self._synced and self._bad == {"garbage"}:  # joined the stream mid-frame
                self.sync_bytes += self._bad_bytes
            else:
                self.bytes_discarded += self._bad_bytes
                if "checksum" in self._bad:
                    self.checksum_errors += 1
                elif "format" in self._bad:
                    self.format_errors += 1
                else:
                    self.resyncs += 1
        self._bad = set()
        self._bad_bytes = 0


FT300_STREAM = StreamFormat(
    name="ft300",
    header=b"\x20\x4e",
    fields=tuple(StreamField(a, "i16", 0.01 if a[0] == "f" else 0.001) for a in AXES),
    checksum="crc16-modbus",
    checksum_from=0,
    rate_hz=100.0,
    range=(300.0, 300.0, 300.0, 30.0, 30.0, 30.0),
    description="Robotiq FT 300 data stream (started by writing 0x0200 to register 410)",
)

FTC_1K = StreamFormat(
    name="ftc-1k",
    header=b"\xa5\x5a",
    fields=(StreamField("seq", "u16"), StreamField("t_device", "u32", 1000.0),
            *(StreamField(a, "i32", 1e-4 if a[0] == "f" else 1e-5) for a in AXES),
            StreamField("status", "u8")),
    checksum="crc16-ccitt",
    checksum_from=2,
    rate_hz=1000.0,
    description="ftc-hw 1 kHz stream: sequence number, device clock (us), int32 counts, status, CRC-16",
)

FORMATS: dict[str, StreamFormat] = {f.name: f for f in (FT300_STREAM, FTC_1K)}


def stream_format(spec: str | Mapping[str, Any]) -> StreamFormat:
    """A built-in format by name, or a format table (see :meth:`StreamFormat.from_dict`)."""
    if isinstance(spec, str):
        try:
            return FORMATS[spec]
        except KeyError:
            raise ValueError(f"unknown stream format {spec!r} (built-in: {', '.join(FORMATS)})") from None
    return StreamFormat.from_dict(spec)
