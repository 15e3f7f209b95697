"""Modbus register maps of F/T sensors, as data: where each axis lives, its type, scale, byte and word
order, the identity registers and (FT 300) the stream-select register. No I/O: registers (16-bit
ints) in, SI wrench out, and the reverse for emulators.

A map in a scene (``[devices.params.map]``, or ``map = "ft300"`` for a built-in one)::

    function = 3                     # 3: holding registers (FC03), 4: input registers (FC04)
    byte_order = "big"               # bytes inside one register (Modbus: big)
    word_order = "big"               # registers of a 32-bit value: "big" = high word first
    range = [300, 300, 300, 30, 30, 30]           # full scale (SI); saturation at it
    axes = [{name = "fx", address = 180, type = "int16", scale = 0.01}, ...]   # all six
    status = {address = 186, type = "uint16"}     # optional: bit i = axis i saturated
    identity = [{name = "serial", address = 510, count = 4, decoder = "ascii"}]
"""
from __future__ import annotations

import math
import struct
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from .errors import FrameFormatError
from .stream import AXES

REGISTER_TYPES: dict[str, tuple[int, str]] = {  # name -> (registers, struct code)
    "int16": (1, "h"), "uint16": (1, "H"), "int32": (2, "i"), "uint32": (2, "I"), "float32": (2, "f"),
}


@dataclass(frozen=True)
class RegisterField:
    name: str
    address: int
    type: str = "int16"
    scale: float = 1.0  # SI per count

    @property
    def count(self) -> int:
        return REGISTER_TYPES[self.type][0]


@dataclass(frozen=True)
class IdentityField:
    name: str
    address: int
    count: int
    decoder: str = "ascii"


def _ascii(regs: Sequence[int]) -> str:
    return b"".join(r.to_bytes(2, "big") for r in regs).rstrip(b"\0 ").decode("ascii", "replace")


def _robotiq_firmware(regs: Sequence[int]) -> str:
    # rq_sensor_com.c: "%c%c%c-%hhu.%hhu.%hhu" of the 6 bytes of registers 500-502
    b = b"".join(r.to_bytes(2, "big") for r in regs[:3])
    return f"{b[:3].decode('ascii', 'replace')}-{b[3]}.{b[4]}.{b[5]}"


def _robotiq_serial(regs: Sequence[int]) -> str:
    # rq_sensor_com.c: 3 characters, then a 32-bit number from registers 512-513 (low word first)
    b = b"".join(r.to_bytes(2, "big") for r in regs[:4])
    number = (b[6] << 24) | (b[7] << 16) | (b[4] << 8) | b[5]
    return "UNKNOWN" if number == 0 else f"{b[:3].decode('ascii', 'replace')}-{number:04d}"


def _uint16(regs: Sequence[int]) -> str:
    return str(regs[0])


IDENTITY_DECODERS: dict[str, Callable[[Sequence[int]], str]] = {
    "ascii": _ascii, "robotiq-firmware": _robotiq_firmware, "robotiq-serial": _robotiq_serial, "uint16": _uint16,
}


def encode_identity(decoder: str, value: str, count: int) -> list[int]:
    """Registers that ``decoder`` turns back into ``value`` (emulators)."""
    if decoder == "uint16":
        return [int(value) & 0xFFFF] + [0] * (count - 1)
    if decoder == "robotiq-firmware":
        prefix, _, version = value.partition("-")
        nums = [int(x) for x in version.split(".")]
        b = prefix.encode("ascii")[:3].ljust(3, b" ") + bytes(nums[:3])
    elif decoder == "robotiq-serial":
        prefix, _, number = value.partition("-")
        n = int(number)
        b = prefix.encode("ascii")[:3].ljust(3, b" ") + b"\0" + bytes([(n >> 8) & 0xFF, n & 0xFF,
                                                                       (n >> 24) & 0xFF, (n >> 16) & 0xFF])
    elif decoder == "ascii":
        b = value.encode("ascii")
    else:
        raise ValueError(f"unknown identity decoder {decoder!r}")
    b = b[:2 * count].ljust(2 * count, b"\0")
    return [int.from_bytes(b[2 * i:2 * i + 2], "big") for i in range(count)]


@dataclass(frozen=True)
class RegisterMap:
    name: str
    axes: tuple[RegisterField, ...]  # fx, fy, fz, tx, ty, tz in that order
    function: int = 3
    byte_order: str = "big"
    word_order: str = "big"
    range: tuple[float, ...] | None = None
    status: RegisterField | None = None
    identity: tuple[IdentityField, ...] = ()
    stream_register: int | None = None  # FT 300: writing stream_value here starts the data stream
    stream_value: int | None = None
    description: str = ""

    def __post_init__(self) -> None:
        if tuple(a.name for a in self.axes) != AXES:
            raise ValueError(f"{self.name}: axes must be {AXES} in that order")
        for f in (*self.axes, *([self.status] if self.status else [])):
            if f.type not in REGISTER_TYPES:
                raise ValueError(f"{self.name}: {f.name}: unknown type {f.type!r} ({', '.join(REGISTER_TYPES)})")
            if not 0 <= f.address <= 0xFFFF - f.count + 1:
                raise ValueError(f"{self.name}: {f.name}: address {f.address} out of 0..65535")
            if not f.scale or not math.isfinite(f.scale):
                raise ValueError(f"{self.name}: {f.name}: scale must be finite and non-zero")
        if self.status is not None and self.status.type == "float32":
            raise ValueError(f"{self.name}: status must be an integer type")
        if self.function not in (3, 4):
            raise ValueError(f"{self.name}: function must be 3 (holding) or 4 (input registers)")
        if self.byte_order not in ("big", "little") or self.word_order not in ("big", "little"):
            raise ValueError(f"{self.name}: byte_order and word_order are 'big' or 'little'")
        if self.range is not None and len(self.range) != 6:
            raise ValueError(f"{self.name}: range must have 6 values")
        for i in self.identity:
            if i.decoder not in IDENTITY_DECODERS or i.count < 1:
                raise ValueError(f"{self.name}: identity {i.name}: decoder one of {', '.join(IDENTITY_DECODERS)}")
        fields = self._data_fields()
        start, count = self.block()
        if count > 125:
            raise ValueError(f"{self.name}: axes span {count} registers; one read holds at most 125")
        used: set[int] = set()
        for f in fields:
            regs = set(range(f.address, f.address + f.count))
            if used & regs:
                raise ValueError(f"{self.name}: {f.name} overlaps another field")
            used |= regs
        del start

    def _data_fields(self) -> tuple[RegisterField, ...]:
        return (*self.axes, self.status) if self.status is not None else self.axes

    def block(self) -> tuple[int, int]:
        """``(first address, register count)`` of one read covering every axis (and the status)."""
        fields = self._data_fields()
        lo = min(f.address for f in fields)
        hi = max(f.address + f.count for f in fields)
        return lo, hi - lo

    # -- registers <-> values --------------------------------------------------------------------------
    def read_field(self, f: RegisterField, regs: Sequence[int]) -> float | int:
        """The raw value (counts) of field ``f`` from its registers, in address order."""
        words = list(regs) if self.word_order == "big" else list(reversed(regs))
        raw = b"".join(int(w).to_bytes(2, self.byte_order) for w in words)  # big-endian value bytes
        return struct.unpack(">" + REGISTER_TYPES[f.type][1], raw)[0]

    def decode(self, registers: Sequence[int], start: int | None = None) -> tuple[tuple[float, ...], int | None]:
        """``(wrench SI, status or None)`` from the registers of :meth:`block` (read from ``start``)."""
        lo, count = self.block()
        start = lo if start is None else start
        if len(registers) < lo - start + count or lo < start:
            raise FrameFormatError(f"{self.name}: expected {count} registers from {lo}, got {len(registers)} "
                                   f"from {start}", consumed=0)
        w = []
        for f in self.axes:
            off = f.address - start
            x = self.read_field(f, registers[off:off + f.count]) * f.scale
            if not math.isfinite(x):
                raise FrameFormatError(f"{self.name}: non-finite {f.name}", consumed=0)
            w.append(float(x))
        status = None
        if self.status is not None:
            off = self.status.address - start
            status = int(self.read_field(self.status, registers[off:off + self.status.count]))
        return tuple(w), status

    def encode(self, wrench: Sequence[float], status: int = 0) -> dict[int, int]:
        """``{address: register}`` holding ``wrench`` (rounded and clipped to each field's type)."""
        out: dict[int, int] = {}
        for f, v in zip(self.axes, wrench, strict=True):
            out.update(self._encode_field(f, float(v) / f.scale))
        if self.status is not None:
            out.update(self._encode_field(self.status, status))
        return out

    def _encode_field(self, f: RegisterField, counts: float) -> dict[int, int]:
        n, code = REGISTER_TYPES[f.type]
        if code != "f":
            bits = 16 * n
            lo, hi = (0, (1 << bits) - 1) if code.isupper() else (-(1 << (bits - 1)), (1 << (bits - 1)) - 1)
            counts = min(max(round(counts), lo), hi)
        raw = struct.pack(">" + code, counts)
        words = [int.from_bytes(raw[2 * i:2 * i + 2], self.byte_order) for i in range(n)]
        regs = words if self.word_order == "big" else list(reversed(words))
        return {f.address + i: r for i, r in enumerate(regs)}

    def decode_identity(self, field: IdentityField, registers: Sequence[int]) -> str:
        return IDENTITY_DECODERS[field.decoder](registers)

    # -- data ------------------------------------------------------------------------------------------
    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> RegisterMap:
        try:
            axes_by_name = {str(a["name"]): a for a in d["axes"]}
            axes = tuple(RegisterField(n, int(axes_by_name[n]["address"]), str(axes_by_name[n].get("type", "int16")),
                                       float(axes_by_name[n].get("scale", 1.0))) for n in AXES)
            st = d.get("status")
            status = None if st is None else RegisterField("status", int(st["address"]),
                                                            str(st.get("type", "uint16")))
            identity = tuple(IdentityField(str(i["name"]), int(i["address"]), int(i.get("count", 1)),
                                           str(i.get("decoder", "ascii"))) for i in d.get("identity", ()))
            rng = d.get("range")
            return cls(name=str(d.get("name", "custom")), axes=axes, function=int(d.get("function", 3)),
                       byte_order=str(d.get("byte_order", "big")), word_order=str(d.get("word_order", "big")),
                       range=None if rng is None else tuple(float(x) for x in rng), status=status,
                       identity=identity,
                       stream_register=None if d.get("stream_register") is None else int(d["stream_register"]),
                       stream_value=None if d.get("stream_value") is None else int(d["stream_value"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"register map table: {exc!r}") from None


FT300_MAP = RegisterMap(
    name="ft300",
    axes=tuple(RegisterField(a, 180 + i, "int16", 0.01 if i < 3 else 0.001) for i, a in enumerate(AXES)),
    function=3,
    range=(300.0, 300.0, 300.0, 30.0, 30.0, 30.0),
    identity=(IdentityField("firmware", 500, 3, "robotiq-firmware"),
              IdentityField("serial", 510, 4, "robotiq-serial"),
              IdentityField("year", 514, 1, "uint16")),
    stream_register=410,
    stream_value=0x0200,
    description="Robotiq FT 300: Fx..Mz at 180-185 (F/100 N, M/1000 N m), identity at 500/510/514",
)

GENERIC_FLOAT32_MAP = RegisterMap(
    name="generic-float32",
    axes=tuple(RegisterField(a, 2 * i, "float32", 1.0) for i, a in enumerate(AXES)),
    function=4,
    status=RegisterField("status", 12, "uint16"),
    identity=(IdentityField("serial", 100, 8, "ascii"),),
    description="float32 N and N m in input registers 0-11 (high word first), status bits at 12",
)

MAPS: dict[str, RegisterMap] = {m.name: m for m in (FT300_MAP, GENERIC_FLOAT32_MAP)}


def register_map(spec: str | Mapping[str, Any]) -> RegisterMap:
    """A built-in map by name, or a map table (see :meth:`RegisterMap.from_dict`)."""
    if isinstance(spec, str):
        try:
            return MAPS[spec]
        except KeyError:
            raise ValueError(f"unknown register map {spec!r} (built-in: {', '.join(MAPS)})") from None
    return RegisterMap.from_dict(spec)
