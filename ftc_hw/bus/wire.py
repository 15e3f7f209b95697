"""The bus's frames as compact binary messages, for carrying them between processes and machines
(:mod:`ftc_hw.bus.remote`). A codec: bytes in, frames out, no I/O.

Every message starts with a 5-byte header: ``b"FT"``, the format's major and minor version (u8
each) and the frame kind (u8: 1 wrench, 2 joints, 3 contact event, 4 device event); then the body,
little-endian, fields in the order below. Times are int64 ns, ``t_device_ns`` absent is
``INT64_MIN``; strings are UTF-8 with a u8 (a message: u16) length; arrays are float64.

- wrench: ``t_host_ns, t_device_ns, seq`` (i64), ``flags`` (u32), ``source``, 6 floats;
- joints: ``t_host_ns, t_device_ns, seq``, ``flags``, ``n`` (u8), ``has_tau`` (u8), ``source``,
  ``q, qd, current`` (n floats each), ``tau`` (n floats if ``has_tau``);
- contact event: ``t_host_ns``, ``kind`` (u8: onset, update, offset, exceedance), ``contact_id`` (u32),
  ``probability, duration_s, peak_force, impulse`` (f64), ``link``, ``point, force, point_std`` (3
  floats each), the flags (u8 count, then each a string); from minor version 1 whether it carries its limits
  (u8), then, if it does, ``region``, ``region_from``, ``limit_kind`` (strings), ``class_assumed`` (u8),
  ``limit_n, margin_n, effective_mass_kg, speed_mps, permissible_speed_mps`` (f64); from minor version 2
  its class: ``contact_class``, ``intent`` (strings), ``p_quasi_static, p_guidance`` (f64), the class's
  features (u8 count, then each a name and an f64);
- device event: ``t_host_ns``, ``source``, ``kind``, ``message`` (u16 length), the counters (u8
  count, then each a name and an f64); ``kind`` a string of ``DEVICE_EVENT_KINDS`` (the monitor's
  ``provisional_onset`` and ``provisional_unconfirmed`` among them: docs/monitor.md);
- batch (kind 5): ``count`` (u16), then each message (u32 length, then the message, header and all):
  frames of one topic sent together when they come faster than they can be sent one by one.

Versions: a reader decodes its own major version only (another is :class:`WireVersionError`). A
writer of a newer minor version may append fields after the ones above: an older reader decodes
what it knows and ignores the rest; a message of the reader's own or an older minor version must
end where its fields end. Anything else (wrong magic, unknown kind, truncated, a value a frame
refuses) is :class:`WireError`: the caller counts and drops it.
"""
from __future__ import annotations

import math
import struct
from collections.abc import Mapping
from functools import cache
from typing import Any

import numpy as np

from .frames import (
    ContactEvent,
    DeviceEvent,
    FrameError,
    JointFlag,
    JointFrame,
    LimitCheck,
    WrenchFlag,
    WrenchFrame,
)

MAGIC = b"FT"
MAJOR, MINOR = 1, 2
KIND_WRENCH, KIND_JOINTS, KIND_CONTACT, KIND_DEVICE, KIND_BATCH = 1, 2, 3, 4, 5
CONTACT_KIND_CODES = {"onset": 0, "update": 1, "offset": 2, "exceedance": 3}
_CONTACT_KINDS = {v: k for k, v in CONTACT_KIND_CODES.items()}
NO_DEVICE_TIME = -(2**63)

_HEADER = struct.Struct("<2sBBB")
_SENSOR = struct.Struct("<qqqI")  # t_host_ns, t_device_ns, seq, flags
_WRENCH_HEAD = struct.Struct("<2sBBBqqqIB")  # header, sensor fields, the source's length
_WRENCH_VALUES = struct.Struct("<6d")
_JOINTS_N = struct.Struct("<BB")
_CONTACT = struct.Struct("<qBIdddd")
_LIMIT_VALUES = struct.Struct("<B5d")  # class_assumed, limit_n, margin_n, effective_mass_kg, speed, permissible
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
MAX_BATCH = 0xFFFF
_F64 = struct.Struct("<d")
_P2 = struct.Struct("<dd")
_I64 = struct.Struct("<q")


class WireError(ValueError):
    """A message that is not a frame of ours: wrong magic, unknown kind, truncated, or a bad value."""


class WireForeignError(WireError):
    """Not a frame of ours at all: too short for the header, or another magic."""


class WireVersionError(WireError):
    """A message of another major version of the format than this reader's."""


def encode(frame: Any) -> bytes:
    """The message of one bus frame (WrenchFrame, JointFrame, ContactEvent or DeviceEvent)."""
    if isinstance(frame, WrenchFrame):
        return (_HEADER.pack(MAGIC, MAJOR, MINOR, KIND_WRENCH) + _sensor(frame) + _str(frame.source)
                + frame.wrench.astype("<f8", copy=False).tobytes())
    if isinstance(frame, JointFrame):
        n, tau = len(frame.q), frame.tau
        arrays = np.concatenate([frame.q, frame.qd, frame.current] + ([tau] if tau is not None else []))
        return (_HEADER.pack(MAGIC, MAJOR, MINOR, KIND_JOINTS) + _sensor(frame)
                + _JOINTS_N.pack(n, tau is not None) + _str(frame.source) + arrays.astype("<f8").tobytes())
    if isinstance(frame, ContactEvent):
        head = _CONTACT.pack(frame.t_host_ns, CONTACT_KIND_CODES[frame.kind], frame.contact_id, frame.probability,
                             frame.duration_s, frame.peak_force, frame.impulse)
        vectors = np.concatenate([frame.point, frame.force, frame.point_std]).astype("<f8").tobytes()
        flags = bytes([len(frame.flags)]) + b"".join(_str(f) for f in frame.flags)
        features = frame.class_features
        cls = (_str(frame.contact_class) + _str(frame.intent) + _P2.pack(frame.p_quasi_static, frame.p_guidance)
               + bytes([len(features)]) + b"".join(_str(k) + _F64.pack(float(v)) for k, v in features.items()))
        return (_HEADER.pack(MAGIC, MAJOR, MINOR, KIND_CONTACT) + head + _str(frame.link) + vectors + flags
                + _limits(frame.limits) + cls)
    if isinstance(frame, DeviceEvent):
        counters = bytes([len(frame.counters)]) + b"".join(_str(k) + _F64.pack(float(v))
                                                           for k, v in frame.counters.items())
        return (_HEADER.pack(MAGIC, MAJOR, MINOR, KIND_DEVICE) + _I64.pack(frame.t_host_ns) + _str(frame.source)
                + _str(frame.kind) + _str(frame.message, 2) + counters)
    raise TypeError(f"not a bus frame: {type(frame).__name__}")


def encode_batch(messages: list[bytes]) -> bytes:
    """One message carrying ``messages`` (each from :func:`encode`), in order; at most MAX_BATCH."""
    if not 0 < len(messages) <= MAX_BATCH:
        raise ValueError(f"a batch holds 1 to {MAX_BATCH} messages, got {len(messages)}")
    return (_HEADER.pack(MAGIC, MAJOR, MINOR, KIND_BATCH) + _U16.pack(len(messages))
            + b"".join(_U32.pack(len(m)) + m for m in messages))


def decode_all(data: bytes | bytearray | memoryview) -> list[Any]:
    """The frames of a message or of a batch of them, in order; :class:`WireError` as :func:`decode`
    (for a batch: the first bad message's, or a batch whose lengths do not add up)."""
    buf = bytes(data)
    if len(buf) < _HEADER.size + 2 or buf[4] != KIND_BATCH or buf[:2] != MAGIC or buf[2] != MAJOR:
        return [decode(buf)]
    (count,) = _U16.unpack_from(buf, _HEADER.size)
    pos, out = _HEADER.size + 2, []
    for _ in range(count):
        if pos + 4 > len(buf):
            raise WireError(f"batch: truncated after {len(out)} of {count} messages")
        (n,) = _U32.unpack_from(buf, pos)
        if pos + 4 + n > len(buf):
            raise WireError(f"batch: message {len(out) + 1} of {count} truncated")
        out.append(decode(buf[pos + 4:pos + 4 + n]))
        pos += 4 + n
    if pos != len(buf) and buf[3] <= MINOR:
        raise WireError(f"batch: {len(buf) - pos} bytes after its {count} messages")
    return out


def decode(data: bytes | bytearray | memoryview) -> Any:
    """The frame of one message; :class:`WireError` for anything that is not one of ours."""
    buf = memoryview(data).cast("B") if not isinstance(data, bytes) else data
    if len(buf) > _WRENCH_HEAD.size and buf[4] == KIND_WRENCH:  # the stream that counts: one struct each part
        magic, major, minor, _, t_host, t_dev, seq, flags, n = _WRENCH_HEAD.unpack_from(buf)
        end = _WRENCH_HEAD.size + n
        if (magic == MAGIC and major == MAJOR and n and len(buf) >= end + 48
                and (minor > MINOR or len(buf) == end + 48)):
            values = _WRENCH_VALUES.unpack_from(buf, end)
            if all(map(math.isfinite, values)):
                wrench = np.array(values)
                wrench.flags.writeable = False
                try:
                    source = bytes(buf[_WRENCH_HEAD.size:end]).decode("utf-8")
                except UnicodeDecodeError:
                    raise WireError("kind 1: the source is not UTF-8") from None
                return WrenchFrame(t_host, None if t_dev == NO_DEVICE_TIME else t_dev, seq, source, wrench,
                                   _wrench_flag(flags))
        # anything odd: the general path says what
    if len(buf) < _HEADER.size:
        raise WireForeignError(f"{len(buf)} bytes: shorter than the header")
    magic, major, minor, kind = _HEADER.unpack_from(buf)
    if magic != MAGIC:
        raise WireForeignError(f"not an ftc-hw frame (magic {bytes(magic)!r})")
    if major != MAJOR:
        raise WireVersionError(f"format version {major}.{minor}: this reader decodes {MAJOR}.x")
    if kind == KIND_BATCH:
        raise WireError("a batch of messages: decode_all takes it apart")
    reader = _Reader(buf, _HEADER.size, minor)
    try:
        frame = _DECODERS[kind](reader) if kind in _DECODERS else None
    except (struct.error, UnicodeDecodeError, IndexError) as exc:
        raise WireError(f"kind {kind}: truncated or malformed ({exc})") from None
    except FrameError as exc:
        raise WireError(f"kind {kind}: {exc}") from None
    if frame is None:
        raise WireError(f"unknown frame kind {kind}")
    if reader.pos != len(buf) and minor <= MINOR:
        raise WireError(f"kind {kind}: {len(buf) - reader.pos} bytes after the frame's last field")
    return frame


class _Reader:
    __slots__ = ("buf", "minor", "pos")

    def __init__(self, buf, pos: int, minor: int = MINOR) -> None:
        self.buf, self.pos, self.minor = buf, pos, minor

    def unpack(self, s: struct.Struct) -> tuple:
        if self.pos + s.size > len(self.buf):
            raise struct.error(f"needs {s.size} bytes at {self.pos}, has {len(self.buf) - self.pos}")
        out = s.unpack_from(self.buf, self.pos)
        self.pos += s.size
        return out

    def string(self, width: int = 1) -> str:
        n = int.from_bytes(self._take(width), "little")
        return bytes(self._take(n)).decode("utf-8")

    def floats(self, n: int) -> np.ndarray:
        """n float64, finite (a frame's arrays are), as a read-only array the frame may keep."""
        values = self.unpack(_floats(n))
        if not all(map(math.isfinite, values)):
            raise FrameError("a non-finite value")
        a = np.array(values, dtype=np.float64)
        a.flags.writeable = False
        return a

    def byte(self) -> int:
        return self._take(1)[0]

    def _take(self, n: int):
        if self.pos + n > len(self.buf):
            raise struct.error(f"needs {n} bytes at {self.pos}, has {len(self.buf) - self.pos}")
        out = self.buf[self.pos:self.pos + n]
        self.pos += n
        return out


@cache
def _wrench_flag(bits: int) -> WrenchFlag:
    return WrenchFlag(bits)


@cache
def _floats(n: int) -> struct.Struct:
    return struct.Struct(f"<{n}d")


def _sensor(frame: WrenchFrame | JointFrame) -> bytes:
    t_dev = NO_DEVICE_TIME if frame.t_device_ns is None else frame.t_device_ns
    return _SENSOR.pack(frame.t_host_ns, t_dev, frame.seq, int(frame.flags))


def _str(s: str, width: int = 1) -> bytes:
    raw = s.encode("utf-8")
    if len(raw) >= 1 << (8 * width):
        raw = raw[:(1 << (8 * width)) - 1].decode("utf-8", errors="ignore").encode("utf-8")
    return len(raw).to_bytes(width, "little") + raw


def _device_time(t: int) -> int | None:
    return None if t == NO_DEVICE_TIME else t


def _wrench(r: _Reader) -> WrenchFrame:
    t_host, t_dev, seq, flags = r.unpack(_SENSOR)
    source = r.string()
    if not source:
        raise FrameError("an empty source")
    return WrenchFrame(t_host, _device_time(t_dev), seq, source, r.floats(6), WrenchFlag(flags))


def _joints(r: _Reader) -> JointFrame:
    t_host, t_dev, seq, flags = r.unpack(_SENSOR)
    n, has_tau = r.unpack(_JOINTS_N)
    source = r.string()
    if n < 1 or not source:
        raise FrameError(f"{n} joints, source {source!r}")
    q, qd, current = r.floats(n), r.floats(n), r.floats(n)
    tau = r.floats(n) if has_tau else None
    return JointFrame(t_host, _device_time(t_dev), seq, source, q, qd, current, tau, JointFlag(flags))


def _contact(r: _Reader) -> ContactEvent:
    t_host, kind, cid, probability, duration, peak, impulse = r.unpack(_CONTACT)
    if kind not in _CONTACT_KINDS:
        raise FrameError(f"unknown contact event kind code {kind}")
    link = r.string()
    point, force, std = r.floats(3), r.floats(3), r.floats(3)
    flags = tuple(r.string() for _ in range(r.byte()))
    limits = None
    if r.minor >= 1 and r.byte():  # its limits, from minor version 1 on
        region, origin, limit_kind = r.string(), r.string(), r.string()
        assumed, *values = r.unpack(_LIMIT_VALUES)
        limits = LimitCheck(region, origin, limit_kind, bool(assumed), *values)
    cls: dict[str, Any] = {}
    if r.minor >= 2:  # the contact's class, from minor version 2 on
        cls["contact_class"], cls["intent"] = r.string(), r.string()
        cls["p_quasi_static"], cls["p_guidance"] = r.unpack(_P2)
        cls["class_features"] = {r.string(): r.unpack(_F64)[0] for _ in range(r.byte())}
    return ContactEvent.make(t_host, _CONTACT_KINDS[kind], link, point, force, std, flags=flags,
                             probability=probability, contact_id=cid, duration_s=duration, peak_force=peak,
                             impulse=impulse, limits=limits, **cls)


def _limits(c: LimitCheck | None) -> bytes:
    if c is None:
        return b"\x00"
    return (b"\x01" + _str(c.region) + _str(c.region_from) + _str(c.limit_kind)
            + _LIMIT_VALUES.pack(c.class_assumed, c.limit_n, c.margin_n, c.effective_mass_kg, c.speed_mps,
                                 c.permissible_speed_mps))


def _device(r: _Reader) -> DeviceEvent:
    (t_host,) = r.unpack(_I64)
    source, kind, message = r.string(), r.string(), r.string(2)
    counters: Mapping[str, float] = {r.string(): r.unpack(_F64)[0] for _ in range(r.byte())}
    return DeviceEvent.make(t_host, source, kind, message, counters)  # type: ignore[arg-type]


_DECODERS = {KIND_WRENCH: _wrench, KIND_JOINTS: _joints, KIND_CONTACT: _contact, KIND_DEVICE: _device}
