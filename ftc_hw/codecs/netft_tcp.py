"""ATI Net F/T's TCP interface (the box's TCP port 49151): 20-byte commands, replies that begin with the
header 0x12 0x34. No I/O. Sources (``sim_devices/SOURCES.md``, Net F/T): ATI's Net F/T manual
(9620-05-NET FT, section 11 "TCP Interface") and Ethernet Axia manual (9610-05, section 10), and the ROS 2
driver of UTNuclearRoboticsPublic/netft_utils, which reads the calibration here.

Every field is in network byte order (big-endian). A command is always 20 bytes, its first byte the code::

    READFT (0): read the F/T values, bias, reset the monitor-condition latch
     0        1                                              16          18            20
    +--------+----------------------------------------------+-----------+-------------+
    |  0x00  |            reserved (15 bytes, all 0)        | MCEnable  | sysCommands |
    +--------+----------------------------------------------+-----------+-------------+
                                                              uint16:     uint16: bit 0 bias,
                                                              a bit per   bit 1 clear the monitor
                                                              monitor     condition latch
                                                              condition

    READCALINFO (1): read the calibration info
     0        1                                                                       20
    +--------+------------------------------------------------------------------------+
    |  0x01  |                      reserved (19 bytes, all 0)                        |
    +--------+------------------------------------------------------------------------+

    WRITETRANSFORM (2): the tool transformation
     0        1          2           3                                     15          20
    +--------+----------+-----------+-------------------------------------+-----------+
    |  0x02  | distUnits| angleUnits| int16 dx dy dz rx ry rz (x 100)     | reserved  |
    +--------+----------+-----------+-------------------------------------+-----------+
              1 in, 2 ft, 3 mm,      1 degrees, 2 radians                  (5 bytes, 0)
              4 cm, 5 m

    WRITETHRESHOLD (3): a monitor condition
     0        1        2       3            4            5               7            20
    +--------+--------+-------+------------+------------+---------------+------------+
    |  0x03  | index  | axis  | outputCode | comparison | compareValue  | reserved   |
    +--------+--------+-------+------------+------------+---------------+------------+
              0-31     0-5:    uint8        int8: 1 >,   int16 (divided   (13 bytes, 0)
                       Fx..Tz               -1 <         by the 16-bit
                                                         scale factor)

Replies (box -> client)::

    READFT reply, 16 bytes
     0          2          4                                                           16
    +----------+----------+------------------------------------------------------------+
    |  0x1234  |  status  | int16 Fx Fy Fz Tx Ty Tz: counts / that axis's scale factor  |
    +----------+----------+------------------------------------------------------------+
                 the upper 16 bits of the 32-bit status word

    READCALINFO reply, 24 bytes
     0          2         3          4                  8                  12              24
    +----------+---------+----------+------------------+------------------+---------------+
    |  0x1234  | force   | torque   | countsPerForce   | countsPerTorque  | scaleFactors  |
    |          | units   | units    | uint32           | uint32           | uint16 x 6    |
    +----------+---------+----------+------------------+------------------+---------------+
                 1 lbf, 2 N, 3 klbf,   1 lbf-in, 2 lbf-ft, 3 N m, 4 N mm, 5 kgf cm, 6 kN m
                 4 kN, 5 kgf, 6 gf

    Write response (to WRITETRANSFORM and WRITETHRESHOLD), 4 bytes
     0          2              3          4
    +----------+--------------+----------+
    |  0x1234  | commandEcho  |  status  |   status 0: done, nonzero: not
    +----------+--------------+----------+

A 16-bit value is the 32-bit count (what RDT sends) divided by the axis's scale factor: ATI's manuals give
it as "actual ft value * calibration counts per unit / 16-bit scaling factor". Bad bytes raise
:class:`TcpCommandError` (a command) or :class:`~ftc_hw.codecs.errors.FrameFormatError` (a reply), never
anything else.
"""
from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass

from .errors import FrameFormatError
from .netft_rdt import HEADER, Calibration

TCP_PORT = 49151
COMMAND_SIZE = 20
READFT, READCALINFO, WRITETRANSFORM, WRITETHRESHOLD = 0, 1, 2, 3
COMMANDS = {READFT: "READFT", READCALINFO: "READCALINFO", WRITETRANSFORM: "WRITETRANSFORM",
            WRITETHRESHOLD: "WRITETHRESHOLD"}
SYS_BIAS, SYS_CLEAR_LATCH = 0x0001, 0x0002  # READFT sysCommands bits
# unit codes of the calibration-info reply, and the unit strings the box's pages use for them
FORCE_UNIT_NAMES = {1: "lbf", 2: "N", 3: "klbf", 4: "kN", 5: "kgf", 6: "gf"}
TORQUE_UNIT_NAMES = {1: "lbf-in", 2: "lbf-ft", 3: "Nm", 4: "Nmm", 5: "kgf-cm", 6: "kNm"}
DISTANCE_UNITS = {1: "in", 2: "ft", 3: "mm", 4: "cm", 5: "m"}
ANGLE_UNITS = {1: "degrees", 2: "radians"}
INT16 = (-(1 << 15), (1 << 15) - 1)

_READFT = struct.Struct("!B15sHH")
_CALINFO_CMD = struct.Struct("!B19s")
_TRANSFORM = struct.Struct("!BBB6h5s")
_THRESHOLD = struct.Struct("!BBBBbh13s")
_FT_REPLY = struct.Struct("!HH6h")
_CAL_REPLY = struct.Struct("!HBBII6H")
_WRITE_REPLY = struct.Struct("!HBB")
FT_REPLY_SIZE, CAL_REPLY_SIZE, WRITE_REPLY_SIZE = _FT_REPLY.size, _CAL_REPLY.size, _WRITE_REPLY.size  # 16, 24, 4


class TcpCommandError(FrameFormatError):
    """A command the box cannot take: ``command`` is its code when the first byte names a known command
    (a write with a field out of range: the box answers it with a nonzero write status), else None."""

    def __init__(self, message: str, command: int | None = None) -> None:
        super().__init__(message, consumed=COMMAND_SIZE)
        self.command = command


@dataclass(frozen=True)
class ReadFT:
    mc_enable: int = 0
    sys_commands: int = 0

    @property
    def bias(self) -> bool:
        return bool(self.sys_commands & SYS_BIAS)

    @property
    def clear_latch(self) -> bool:
        return bool(self.sys_commands & SYS_CLEAR_LATCH)


@dataclass(frozen=True)
class ReadCalInfo:
    pass


@dataclass(frozen=True)
class WriteTransform:
    distance_units: int
    angle_units: int
    transform: tuple[int, ...]  # dx dy dz rx ry rz, each x 100


@dataclass(frozen=True)
class WriteThreshold:
    index: int
    axis: int
    output_code: int
    comparison: int
    compare_value: int


TcpCommand = ReadFT | ReadCalInfo | WriteTransform | WriteThreshold


@dataclass(frozen=True)
class CalInfo:
    """The READCALINFO reply: unit codes, counts per force and torque unit, the six 16-bit scale factors."""

    force_units: int
    torque_units: int
    counts_per_force: int
    counts_per_torque: int
    scale_factors: tuple[int, ...]

    def calibration(self) -> Calibration:
        """The counts per unit as :class:`~ftc_hw.codecs.netft_rdt.Calibration` (units as the pages spell them)."""
        return Calibration(float(self.counts_per_force), float(self.counts_per_torque),
                           FORCE_UNIT_NAMES[self.force_units], TORQUE_UNIT_NAMES[self.torque_units],
                           fields=("countsPerForce", "countsPerTorque"))


@dataclass(frozen=True)
class FTReply:
    status: int  # the upper 16 bits of the status word
    counts: tuple[int, ...]  # six int16


# -- commands --------------------------------------------------------------------------------------
def encode_command(cmd: TcpCommand) -> bytes:
    if isinstance(cmd, ReadFT):
        return _READFT.pack(READFT, bytes(15), cmd.mc_enable, cmd.sys_commands)
    if isinstance(cmd, ReadCalInfo):
        return _CALINFO_CMD.pack(READCALINFO, bytes(19))
    if isinstance(cmd, WriteTransform):
        return _TRANSFORM.pack(WRITETRANSFORM, cmd.distance_units, cmd.angle_units, *cmd.transform, bytes(5))
    return _THRESHOLD.pack(WRITETHRESHOLD, cmd.index, cmd.axis, cmd.output_code, cmd.comparison, cmd.compare_value,
                           bytes(13))


def decode_command(data: bytes) -> TcpCommand:
    """One 20-byte command. TcpCommandError for another length, an unknown code, or a write whose units,
    index, axis or comparison are out of the documented ranges (its ``command`` then set). The reserved
    bytes ("should be all 0s") are not checked."""
    if len(data) != COMMAND_SIZE:
        raise TcpCommandError(f"Net F/T TCP command of {len(data)} bytes, expected {COMMAND_SIZE}")
    code = data[0]
    if code == READFT:
        _, _, mc_enable, sys_commands = _READFT.unpack(data)
        return ReadFT(mc_enable, sys_commands)
    if code == READCALINFO:
        return ReadCalInfo()
    if code == WRITETRANSFORM:
        _, dist, angle, *transform, _ = _TRANSFORM.unpack(data)
        if dist not in DISTANCE_UNITS or angle not in ANGLE_UNITS:
            raise TcpCommandError(f"WRITETRANSFORM units {dist}/{angle}: distance 1-5, angle 1-2", code)
        return WriteTransform(dist, angle, tuple(transform))
    if code == WRITETHRESHOLD:
        _, index, axis, output, comparison, value, _ = _THRESHOLD.unpack(data)
        if index > 31 or axis > 5 or comparison not in (1, -1):
            raise TcpCommandError(f"WRITETHRESHOLD index {index} (0-31), axis {axis} (0-5), comparison "
                                  f"{comparison} (1 or -1)", code)
        return WriteThreshold(index, axis, output, comparison, value)
    raise TcpCommandError(f"Net F/T TCP command code {code} not known (0-3)")


# -- replies ---------------------------------------------------------------------------------------
def encode_ft_reply(reply: FTReply) -> bytes:
    return _FT_REPLY.pack(HEADER, reply.status & 0xFFFF, *reply.counts)


def decode_ft_reply(data: bytes) -> FTReply:
    _check(data, FT_REPLY_SIZE, "READFT")
    _, status, *counts = _FT_REPLY.unpack(data)
    return FTReply(status, tuple(counts))


def encode_cal_info(info: CalInfo) -> bytes:
    return _CAL_REPLY.pack(HEADER, info.force_units, info.torque_units, info.counts_per_force,
                           info.counts_per_torque, *info.scale_factors)


def decode_cal_info(data: bytes) -> CalInfo:
    """FrameFormatError for another length, header, an unknown unit code, zero counts per unit or a zero
    scale factor."""
    _check(data, CAL_REPLY_SIZE, "READCALINFO")
    _, fu, tu, cpf, cpt, *factors = _CAL_REPLY.unpack(data)
    if fu not in FORCE_UNIT_NAMES or tu not in TORQUE_UNIT_NAMES:
        raise FrameFormatError(f"READCALINFO unit codes force {fu}, torque {tu}: expected 1-6", consumed=len(data))
    if cpf == 0 or cpt == 0 or 0 in factors:
        raise FrameFormatError("READCALINFO with zero counts per unit or a zero scale factor", consumed=len(data))
    return CalInfo(fu, tu, cpf, cpt, tuple(factors))


def encode_write_reply(command: int, status: int) -> bytes:
    return _WRITE_REPLY.pack(HEADER, command, status)


def decode_write_reply(data: bytes) -> tuple[int, int]:
    """(commandEcho, status) of a write response."""
    _check(data, WRITE_REPLY_SIZE, "write")
    _, command, status = _WRITE_REPLY.unpack(data)
    return command, status


def _check(data: bytes, size: int, what: str) -> None:
    if len(data) != size:
        raise FrameFormatError(f"{what} reply of {len(data)} bytes, expected {size}", consumed=len(data))
    if int.from_bytes(data[:2], "big") != HEADER:
        raise FrameFormatError(f"{what} reply header {data[:2].hex()}, expected 1234", consumed=len(data))


# -- the box's values ------------------------------------------------------------------------------
def cal_info(cal: Calibration, max_range: Sequence[float]) -> CalInfo:
    """The READCALINFO reply of a box with ``cal`` (counts per unit, units) rated ``max_range`` (six, in its
    units): each scale factor the smallest that fits the axis's rated counts in int16. FrameFormatError when
    the counts per unit are not whole uint32 or a unit has no code."""
    codes = {v: k for k, v in FORCE_UNIT_NAMES.items()}, {v: k for k, v in TORQUE_UNIT_NAMES.items()}
    fu = codes[0].get(cal.force_unit)
    tu = codes[1].get(cal.torque_unit.replace("N-m", "Nm").replace("N-mm", "Nmm").replace("kN-m", "kNm"))
    if fu is None or tu is None:
        raise FrameFormatError(f"units {cal.force_unit}/{cal.torque_unit} have no READCALINFO code", consumed=0)
    counts = []
    for x in (cal.counts_per_force, cal.counts_per_torque):
        if not (float(x).is_integer() and 0 < x < 1 << 32):
            raise FrameFormatError(f"counts per unit {x} are not a uint32", consumed=0)
        counts.append(int(x))
    per_unit = [counts[0]] * 3 + [counts[1]] * 3
    factors = tuple(min(0xFFFF, max(1, math.ceil(abs(r) * c / INT16[1]))) for r, c in zip(max_range, per_unit,
                                                                                         strict=True))
    return CalInfo(fu, tu, counts[0], counts[1], factors)


def ft_reply(counts: Sequence[int], scale_factors: Sequence[int], status: int = 0) -> FTReply:
    """The READFT reply for 32-bit ``counts`` (as RDT sends them) and the 32-bit ``status`` word: each count
    divided by its scale factor, rounded, clamped to int16."""
    lo, hi = INT16
    return FTReply((status >> 16) & 0xFFFF,
                   tuple(min(hi, max(lo, round(c / s))) for c, s in zip(counts, scale_factors, strict=True)))

