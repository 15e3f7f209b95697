"""DYNAMIXEL Protocol 2.0 framing: CRC-16, byte stuffing, instruction parsing, status packets.

Packet: ``FF FF FD 00 | ID | LEN_L LEN_H | INST | params... | CRC_L CRC_H`` where LEN counts INST,
params and CRC. CRC-16 (polynomial 0x8005, initial value 0, no reflection) over everything before
the CRC, byte stuffing included. Byte stuffing: in INST and params, every ``FF FF FD`` is sent as
``FF FF FD FD`` (LEN counts the added bytes); the receiver checks the CRC first, then removes it.
Fast Sync/Bulk Read answers are one packet (ID 0xFE) to which every servo appends
``ERR ID data CRC_L CRC_H``, the CRC covering the whole packet up to there, with no stuffing.
Source: ROBOTIS e-manual, Protocol 2.0 and CRC pages; dynamixel_sdk 4.1.0's protocol2_packet_handler.
"""
from __future__ import annotations

from dataclasses import dataclass

HEADER = b"\xff\xff\xfd\x00"
MAX_LENGTH = 1024  # the largest LEN accepted (the SDK's RX/TX buffers hold 1024 bytes)


def _crc_table() -> list[int]:
    table = []
    for i in range(256):
        crc = i << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else (crc << 1)
        table.append(crc & 0xFFFF)
    return table


_TABLE = _crc_table()


def crc16(data: bytes | bytearray | memoryview, crc: int = 0) -> int:
    table = _TABLE
    for b in data:
        crc = ((crc << 8) ^ table[((crc >> 8) ^ b) & 0xFF]) & 0xFFFF
    return crc


def stuff(body: bytes, context: bytes = b"") -> bytes:
    """Insert the stuffing 0xFD after every ``FF FF FD`` of ``body`` (INST and params); ``context``:
    the bytes that precede ``body`` on the wire (a pattern may start there)."""
    if b"\xff\xff\xfd" not in context[-2:] + body:
        return body
    out = bytearray()
    prev = bytearray(context[-2:])
    for b in body:
        out.append(b)
        if b == 0xFD and len(prev) >= 2 and prev[-1] == 0xFF and prev[-2] == 0xFF:
            out.append(0xFD)
        prev.append(b)
        del prev[:-2]
    return bytes(out)


def unstuff(body: bytes, context: bytes = b"") -> bytes:
    """Remove the stuffing from a received INST + params region (``context``: the LEN bytes before it)."""
    if b"\xff\xff\xfd\xfd" not in context[-2:] + body:
        return body
    out = bytearray()
    hist = bytearray(context[-2:])
    i, n = 0, len(body)
    while i < n:
        b = body[i]
        out.append(b)
        hist.append(b)
        del hist[:-3]
        if b == 0xFD and hist[:2] == b"\xff\xff" and i + 1 < n and body[i + 1] == 0xFD:
            hist.clear()
            i += 2  # the stuffing byte
            continue
        i += 1
    return bytes(out)


def packet(dxl_id: int, instruction: int, params: bytes = b"", error: int | None = None) -> bytes:
    """An instruction packet (``error`` None) or a status packet (``instruction`` 0x55), stuffed, with CRC."""
    body = bytes([instruction]) + (b"" if error is None else bytes([error])) + params
    body = stuff(body, (len(body) + 2).to_bytes(2, "little"))
    frame = HEADER + bytes([dxl_id]) + (len(body) + 2).to_bytes(2, "little") + body
    return frame + crc16(frame).to_bytes(2, "little")


def status(dxl_id: int, error: int, params: bytes = b"") -> bytes:
    return packet(dxl_id, 0x55, params, error)


def fast_status(blocks: list[tuple[int, int, bytes]]) -> bytes:
    """The one answer to a Fast Sync/Bulk Read: ``blocks`` of (error, id, data), in bus order."""
    length = 1 + sum(len(d) + 4 for _, _, d in blocks)
    frame = bytearray(HEADER + b"\xfe" + length.to_bytes(2, "little") + b"\x55")
    crc = crc16(frame)
    for err, dxl_id, data in blocks:
        start = len(frame)
        frame += bytes([err, dxl_id]) + data
        crc = crc16(memoryview(frame)[start:], crc)
        frame += crc.to_bytes(2, "little")
        crc = crc16(memoryview(frame)[-2:], crc)
    return bytes(frame)


@dataclass(frozen=True)
class Instruction:
    """A received instruction packet (stuffing removed) or, with ``crc_ok`` False, a damaged one."""

    id: int
    instruction: int
    params: bytes
    crc_ok: bool = True
    raw: bytes = b""


class PacketReader:
    """Turns the received byte stream into :class:`Instruction` s: header search, LEN, CRC, stuffing.

    Bytes that are no packet are skipped (counted in ``skipped``). A packet whose CRC does not match is
    returned with ``crc_ok=False``; the search then resumes right after its header, so a good packet
    swallowed by a damaged one's LEN is still found. ``expire()`` drops an incomplete packet (the
    servo's packet timeout: the rest never came).
    """

    def __init__(self) -> None:
        self.buf = bytearray()
        self.skipped = 0

    def feed(self, data: bytes) -> list[Instruction]:
        self.buf += data
        out: list[Instruction] = []
        buf = self.buf
        while True:
            i = buf.find(HEADER)
            if i < 0:
                keep = 3 if buf[-3:] == HEADER[:3] else 2 if buf[-2:] == HEADER[:2] else 1 if buf[-1:] == b"\xff" else 0
                self.skipped += len(buf) - keep
                del buf[:len(buf) - keep]
                break
            if i:
                self.skipped += i
                del buf[:i]
            if len(buf) < 7:
                break
            length = buf[5] | buf[6] << 8
            if length < 3 or length > MAX_LENGTH:
                self.skipped += 1
                del buf[:1]
                continue
            end = 7 + length
            if len(buf) < end:
                break
            frame = bytes(buf[:end])
            dxl_id, inst = frame[4], frame[7]
            if crc16(frame[:-2]) != (frame[-2] | frame[-1] << 8):
                out.append(Instruction(dxl_id, inst, b"", crc_ok=False, raw=frame))
                self.skipped += 1
                del buf[:1]  # resume the search inside it
                continue
            body = unstuff(frame[7:-2], frame[5:7])
            out.append(Instruction(dxl_id, body[0], body[1:], raw=frame))
            del buf[:end]
        return out

    @property
    def pending(self) -> bool:
        return bool(self.buf)

    def expire(self) -> None:
        self.skipped += len(self.buf)
        self.buf.clear()


def parse_status(frame: bytes) -> tuple[int, int, bytes]:
    """(id, error, params) of one status packet (checks header, LEN and CRC; removes stuffing)."""
    if frame[:4] != HEADER or len(frame) < 11:
        raise ValueError("not a status packet")
    length = frame[5] | frame[6] << 8
    if len(frame) != 7 + length or frame[7] != 0x55:
        raise ValueError("bad length or instruction")
    if crc16(frame[:-2]) != (frame[-2] | frame[-1] << 8):
        raise ValueError("bad CRC")
    body = unstuff(frame[7:-2], frame[5:7])
    return frame[4], body[1], body[2:]
