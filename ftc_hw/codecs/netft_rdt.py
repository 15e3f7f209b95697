"""ATI Net F/T over Ethernet: RDT (Raw Data Transfer) over UDP, and the box's calibration page. No I/O.

Request, 8 bytes, network byte order: uint16 header 0x1234, uint16 command, uint32 sample count (0:
until stopped). Commands (ATI's Net F/T manual, 9620-05-NET FT, "RDT"; 0x0001 from ATI's Java demo
library, ``NetFTRDTCommand``): 0x0000 stop, 0x0001 loop-driven output (one record per packet, ``count``
of them: ATI's library sends it with count 1 for a single record), 0x0002 start real-time (one record
per packet), 0x0003 start buffered (``comrdtbsiz`` records per packet), 0x0004 start multi-unit
streaming, 0x0041 reset the threshold latch, 0x0042 set software bias (the box subtracts the current
reading from what follows). Record, 36 bytes: uint32 rdt_sequence (+1 per packet), uint32 ft_sequence
(the box's internal sample counter), uint32 status, int32 Fx Fy Fz Tx Ty Tz in counts. A packet is
one or more whole records.

Counts to units: the box's configuration page (``/netftapi2.xml``): ``cfgcpf`` and ``cfgcpt`` (counts
per force and torque unit), ``scfgfu`` / ``scfgtu`` (those units), ``comrdtrate`` (the RDT output rate,
Hz) and ``comrdtbsiz`` (records per buffered packet). :func:`parse_calibration` reads it;
:class:`CalibrationError` names what is wrong. The box's other pages (its calibration,
``/netftcalapi.xml``, with ``calcpf``/``calcpt``): :mod:`ftc_hw.codecs.netft_pages`.

Status word: ATI's manual defines its bits; this codec keeps the convention of the project's other
F/T codecs for the bits the emulator sets (bits 0-5: that axis saturated) and treats every other set
bit as the box reporting an error (bit 31 is its summary error bit): :data:`STATUS_ERROR_MASK`.
"""
from __future__ import annotations

import math
import struct
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property

from .errors import CodecError, FrameFormatError

HEADER = 0x1234
CMD_STOP, CMD_START_REALTIME, CMD_START_BUFFERED, CMD_SET_BIAS = 0x0000, 0x0002, 0x0003, 0x0042
CMD_LOOP, CMD_START_MULTI_UNIT, CMD_RESET_LATCH = 0x0001, 0x0004, 0x0041
COMMANDS = {CMD_STOP: "stop", CMD_LOOP: "loop-driven output", CMD_START_REALTIME: "start real-time",
            CMD_START_BUFFERED: "start buffered", CMD_START_MULTI_UNIT: "start multi-unit streaming",
            CMD_RESET_LATCH: "reset threshold latch", CMD_SET_BIAS: "set software bias"}
DEFAULT_PORT = 49152
CALIBRATION_PATH = "/netftapi2.xml"
STATUS_SATURATION_MASK = 0x3F
STATUS_ERROR_MASK = 0xFFFFFFFF & ~STATUS_SATURATION_MASK
STATUS_ERROR = 1 << 31

_REQUEST = struct.Struct("!HHI")
_RECORD = struct.Struct("!III6i")
REQUEST_SIZE = _REQUEST.size  # 8
RECORD_SIZE = _RECORD.size  # 36
INT32 = (-(1 << 31), (1 << 31) - 1)

# SI per unit of the box's force and torque units (scfgfu / scfgtu as the box spells them)
FORCE_UNITS = {"N": 1.0, "kN": 1000.0, "lbf": 4.4482216152605, "klbf": 4448.2216152605, "gf": 0.00980665,
               "kgf": 9.80665}
TORQUE_UNITS = {"Nm": 1.0, "N-m": 1.0, "Nmm": 0.001, "N-mm": 0.001, "kNm": 1000.0, "kN-m": 1000.0,
                "lbf-in": 0.1129848290276167, "lbf-ft": 1.3558179483314004, "kgf-cm": 0.0980665, "gf-cm": 9.80665e-5}


class CalibrationError(CodecError):
    """The box's calibration page is malformed, or disagrees with what the scene says: ``field`` names
    the element (or scene param) at fault."""

    def __init__(self, field: str, problem: str) -> None:
        super().__init__(f"{field}: {problem}", consumed=0)
        self.field = field


@dataclass(frozen=True)
class RdtRequest:
    command: int
    count: int = 0  # records to send, 0: until stopped


@dataclass(frozen=True)
class RdtRecord:
    rdt_sequence: int
    ft_sequence: int
    status: int
    counts: tuple[int, int, int, int, int, int]


@dataclass(frozen=True)
class Calibration:
    """What the adapter needs of the box's configuration. ``scale``: SI per count, per axis."""

    counts_per_force: float
    counts_per_torque: float
    force_unit: str = "N"
    torque_unit: str = "Nm"
    rdt_rate_hz: float | None = None
    buffer_size: int | None = None
    fields: tuple[str, str] = field(default=("cfgcpf", "cfgcpt"), compare=False)  # the page's names of the counts

    @cached_property  # computed once: to_si and to_counts run for every record (7 kHz)
    def scale(self) -> tuple[float, ...]:
        f = FORCE_UNITS[self.force_unit] / self.counts_per_force
        t = TORQUE_UNITS[self.torque_unit] / self.counts_per_torque
        return (f, f, f, t, t, t)

    def to_si(self, counts: Sequence[int]) -> tuple[float, ...]:
        return tuple(c * s for c, s in zip(counts, self.scale, strict=True))

    def to_counts(self, wrench_si: Sequence[float]) -> tuple[int, ...]:
        """The counts the box sends for ``wrench_si``, clamped to int32 (the box's range)."""
        lo, hi = INT32
        values = wrench_si.tolist() if hasattr(wrench_si, "tolist") else wrench_si  # floats, as float(w)
        return tuple(min(hi, max(lo, round(float(w) / s))) for w, s in zip(values, self.scale, strict=True))


# -- requests --------------------------------------------------------------------------------------
def encode_request(command: int, count: int = 0) -> bytes:
    return _REQUEST.pack(HEADER, command, count)


def decode_request(data: bytes) -> RdtRequest:
    """FrameFormatError for a wrong length, header or unknown command."""
    if len(data) != REQUEST_SIZE:
        raise FrameFormatError(f"RDT request of {len(data)} bytes, expected {REQUEST_SIZE}", consumed=len(data))
    header, command, count = _REQUEST.unpack(data)
    if header != HEADER:
        raise FrameFormatError(f"RDT request header {header:#06x}, expected {HEADER:#06x}", consumed=len(data))
    if command not in COMMANDS:
        raise FrameFormatError(f"RDT command {command:#06x} not supported", consumed=len(data))
    return RdtRequest(command, count)


# -- records ---------------------------------------------------------------------------------------
def encode_records(records: Sequence[RdtRecord]) -> bytes:
    return b"".join(_RECORD.pack(r.rdt_sequence & 0xFFFFFFFF, r.ft_sequence & 0xFFFFFFFF, r.status & 0xFFFFFFFF,
                                 *r.counts) for r in records)


def decode_packet(data: bytes, records: int | None = None) -> list[RdtRecord]:
    """The records of one datagram. FrameFormatError when it is empty, not whole records, or not
    ``records`` of them (when given: one in real-time mode, the buffer size in buffered mode)."""
    n, rest = divmod(len(data), RECORD_SIZE)
    if n == 0 or rest:
        raise FrameFormatError(f"RDT packet of {len(data)} bytes: not whole {RECORD_SIZE}-byte records",
                               consumed=len(data))
    if records is not None and n != records:
        raise FrameFormatError(f"RDT packet of {n} records, expected {records}", consumed=len(data))
    out = []
    for i in range(n):
        rdt, ft, status, *counts = _RECORD.unpack_from(data, i * RECORD_SIZE)
        out.append(RdtRecord(rdt, ft, status, tuple(counts)))  # type: ignore[arg-type]
    return out


def status_errors(status: int) -> int:
    """The status word's error bits (0: none)."""
    return status & STATUS_ERROR_MASK


# -- calibration page ------------------------------------------------------------------------------
def encode_calibration(cal: Calibration, extra: dict[str, str] | None = None) -> bytes:
    """The box's calibration page (``/netftapi2.xml``) for ``cal``; ``extra`` adds or replaces elements."""
    fields = {"cfgcpf": _num(cal.counts_per_force), "cfgcpt": _num(cal.counts_per_torque),
              "scfgfu": cal.force_unit, "scfgtu": cal.torque_unit}
    if cal.rdt_rate_hz is not None:
        fields["comrdtrate"] = _num(cal.rdt_rate_hz)
    if cal.buffer_size is not None:
        fields["comrdtbsiz"] = str(cal.buffer_size)
    fields.update(extra or {})
    root = ET.Element("netft")
    for key, value in fields.items():
        ET.SubElement(root, key).text = value
    return b'<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(root)


def parse_calibration(data: bytes) -> Calibration:
    """The calibration on the box's page; CalibrationError naming the element that is missing or wrong."""
    try:
        root = ET.fromstring(data)
    except ET.ParseError as exc:
        raise CalibrationError(CALIBRATION_PATH, f"not well-formed XML ({exc})") from None
    values = {el.tag.rsplit("}", 1)[-1].lower(): (el.text or "").strip() for el in root.iter()}
    cpf = _positive(values, "cfgcpf")
    cpt = _positive(values, "cfgcpt")
    fu = values.get("scfgfu", "N")
    tu = values.get("scfgtu", "N-m")
    if fu not in FORCE_UNITS:
        raise CalibrationError("scfgfu", f"force unit {fu!r} not known (known: {', '.join(FORCE_UNITS)})")
    if tu not in TORQUE_UNITS:
        raise CalibrationError("scfgtu", f"torque unit {tu!r} not known (known: {', '.join(TORQUE_UNITS)})")
    rate = _positive(values, "comrdtrate") if "comrdtrate" in values else None
    bsize = int(_positive(values, "comrdtbsiz")) if "comrdtbsiz" in values else None
    return Calibration(cpf, cpt, fu, tu, rate, bsize)


def _positive(values: dict[str, str], key: str) -> float:
    if key not in values:
        raise CalibrationError(key, "missing from the calibration page")
    try:
        x = float(values[key])
    except ValueError:
        raise CalibrationError(key, f"{values[key]!r} is not a number") from None
    if not math.isfinite(x) or x <= 0:
        raise CalibrationError(key, f"{values[key]!r}: expected a positive number")
    return x


def _num(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else repr(float(x))


def reconcile(box: Calibration | None, *, counts_per_force: float | None = None,
              counts_per_torque: float | None = None, rate_hz: float | None = None,
              buffer_size: int | None = None) -> Calibration:
    """The calibration to decode with: the box's (``None``: not read), with the scene's values where it
    gives them. Where both say something they must agree: CalibrationError naming the field and both
    values. The scene's counts are per N and per N m: a box in other units (lbf, N-mm, ...) is compared
    per SI unit. Without the box's page the scene must give both counts (in N and N m)."""
    if box is None:
        if counts_per_force is None or counts_per_torque is None:
            raise CalibrationError("counts_per_force", "the box's calibration was not read: the scene must give "
                                   "counts_per_force and counts_per_torque")
        return Calibration(counts_per_force, counts_per_torque, rdt_rate_hz=rate_hz, buffer_size=buffer_size)
    si_f, si_t = FORCE_UNITS[box.force_unit], TORQUE_UNITS[box.torque_unit]
    checks = ((box.fields[0], counts_per_force, box.counts_per_force / si_f, _unit_note(box.force_unit, si_f)),
              (box.fields[1], counts_per_torque, box.counts_per_torque / si_t, _unit_note(box.torque_unit, si_t)),
              ("comrdtrate", rate_hz, box.rdt_rate_hz, ""), ("comrdtbsiz", buffer_size, box.buffer_size, ""))
    for name, ours, theirs, note in checks:
        if ours is not None and theirs is not None and not math.isclose(ours, theirs, rel_tol=1e-9):
            raise CalibrationError(name, f"the box says {_num(theirs)}{note}, the scene {_num(ours)}")
    return box


def _unit_note(unit: str, si: float) -> str:
    """How a box's count in a unit other than N or N m is said: per SI unit, from its own unit."""
    return "" if si == 1.0 else f" per SI unit (its unit is {unit})"
