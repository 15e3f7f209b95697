"""Modbus RTU and Modbus TCP (MBAP) framing of requests and responses, as a server sees them.

The adapters use pymodbus as the client; the emulators use these to be the device. No I/O.
"""
from __future__ import annotations

import struct

from .checksums import crc16_modbus
from .errors import ChecksumError, FrameFormatError

_FIXED = {1, 2, 3, 4, 5, 6}  # request: unit, fc, 4 bytes, CRC
_WITH_COUNT = {15, 16}  # request: unit, fc, addr(2), qty(2), byte count, data, CRC


def rtu_encode(unit: int, pdu: bytes) -> bytes:
    frame = bytes([unit]) + pdu
    return frame + crc16_modbus(frame).to_bytes(2, "little")


def rtu_decode_request(buffer: bytes | bytearray) -> tuple[int, tuple[int, bytes] | None]:
    """``(consumed, (unit, pdu))`` for a whole request at the start of ``buffer``, ``(0, None)`` when
    more bytes are needed. Raises :class:`ChecksumError` or :class:`FrameFormatError` (skip ``consumed``)."""
    buf = bytes(buffer)
    if len(buf) < 2:
        return 0, None
    fc = buf[1]
    if fc in _FIXED:
        size = 8
    elif fc in _WITH_COUNT:
        if len(buf) < 7:
            return 0, None
        size = 9 + buf[6]
    else:
        raise FrameFormatError(f"function code {fc} not supported", consumed=1)
    if len(buf) < size:
        return 0, None
    if crc16_modbus(buf[:size - 2]) != int.from_bytes(buf[size - 2:size], "little"):
        raise ChecksumError("RTU request CRC mismatch", consumed=1)
    return size, (buf[0], buf[1:size - 2])


def mbap_encode(tid: int, unit: int, pdu: bytes) -> bytes:
    return struct.pack(">HHHB", tid & 0xFFFF, 0, len(pdu) + 1, unit) + pdu


def mbap_decode(buffer: bytes | bytearray) -> tuple[int, tuple[int, int, bytes] | None]:
    """``(consumed, (transaction id, unit, pdu))`` or ``(0, None)``; :class:`FrameFormatError` on a bad header."""
    buf = bytes(buffer)
    if len(buf) < 7:
        return 0, None
    tid, proto, length, unit = struct.unpack_from(">HHHB", buf)
    if proto != 0 or not 2 <= length <= 254:
        raise FrameFormatError(f"bad MBAP header (protocol {proto}, length {length})", consumed=len(buf))
    size = 6 + length
    if len(buf) < size:
        return 0, None
    return size, (tid, unit, buf[7:size])
