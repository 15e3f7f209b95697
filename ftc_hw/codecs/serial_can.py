"""The byte framing of python-can's ``serial`` interface (python-can 4.6.1, ``can/interfaces/serial``)::

    AA | timestamp uint32 LE (ms) | DLC | arbitration id uint32 LE (flags in bits 29-31) | data | BB

The adapters use python-can itself; the emulators write and read these bytes on their pty master.
"""
from __future__ import annotations

import struct

from .errors import FrameFormatError

CAN_ERR_FLAG = 0x20000000
CAN_RTR_FLAG = 0x40000000
CAN_EFF_FLAG = 0x80000000
START, END = 0xAA, 0xBB


def encode(arbitration_id: int, data: bytes, timestamp_ms: int = 0, *, error_frame: bool = False,
           extended: bool = False) -> bytes:
    aid = arbitration_id & (0x1FFFFFFF if extended else 0x7FF)
    aid |= (CAN_EFF_FLAG if extended else 0) | (CAN_ERR_FLAG if error_frame else 0)
    return (bytes([START]) + struct.pack("<I", timestamp_ms & 0xFFFFFFFF) + bytes([len(data)])
            + struct.pack("<I", aid) + bytes(data) + bytes([END]))


def decode(buffer: bytes | bytearray) -> tuple[int, tuple[int, bytes, bool] | None]:
    """``(consumed, (arbitration id, data, error frame))``; ``(n, None)``: skip n bytes of noise;
    ``(0, None)``: need more. Raises :class:`FrameFormatError` for a bad DLC or end delimiter."""
    buf = bytes(buffer)
    i = buf.find(bytes([START]))
    if i < 0:
        return len(buf), None
    if i > 0:
        return i, None
    if len(buf) < 6:
        return 0, None
    dlc = buf[5]
    if dlc > 8:
        raise FrameFormatError(f"DLC {dlc} > 8", consumed=1)
    size = 11 + dlc
    if len(buf) < size:
        return 0, None
    if buf[size - 1] != END:
        raise FrameFormatError("bad end delimiter", consumed=1)
    (aid,) = struct.unpack_from("<I", buf, 6)
    mask = 0x1FFFFFFF if aid & CAN_EFF_FLAG else 0x7FF
    return size, (aid & mask, buf[10:10 + dlc], bool(aid & CAN_ERR_FLAG))
