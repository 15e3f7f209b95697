"""Checksums used by the frame formats, by name. Pure functions of bytes."""
from __future__ import annotations

import binascii
from collections.abc import Callable
from dataclasses import dataclass


def _crc16_table(poly_reflected: int) -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = (crc >> 1) ^ poly_reflected if crc & 1 else crc >> 1
        table.append(crc)
    return tuple(table)


_MODBUS_TABLE = _crc16_table(0xA001)


def crc16_modbus(data: bytes | bytearray | memoryview) -> int:
    """CRC-16/MODBUS: poly 0x8005 reflected (0xA001), init 0xFFFF. Sent little-endian on the wire."""
    crc = 0xFFFF
    table = _MODBUS_TABLE
    for b in bytes(data):
        crc = (crc >> 8) ^ table[(crc ^ b) & 0xFF]
    return crc


def crc16_ccitt(data: bytes | bytearray | memoryview) -> int:
    """CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, not reflected (binascii's C implementation)."""
    return binascii.crc_hqx(bytes(data), 0xFFFF)


def sum8(data: bytes | bytearray | memoryview) -> int:
    return sum(bytes(data)) & 0xFF


def xor8(data: bytes | bytearray | memoryview) -> int:
    x = 0
    for b in bytes(data):
        x ^= b
    return x


@dataclass(frozen=True)
class Checksum:
    name: str
    func: Callable[[bytes], int]
    size: int  # bytes on the wire


CHECKSUMS: dict[str, Checksum] = {
    c.name: c
    for c in (Checksum("crc16-modbus", crc16_modbus, 2), Checksum("crc16-ccitt", crc16_ccitt, 2),
              Checksum("sum8", sum8, 1), Checksum("xor8", xor8, 1))
}
