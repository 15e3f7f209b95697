"""A Modbus server's application layer: a register bank answering FC03/04 (read), FC06/16 (write).

Framing (RTU CRC, MBAP) is in :mod:`ftc_hw.codecs.modbus_frames`; transports are the emulators'.
"""
from __future__ import annotations

import struct
from collections.abc import Callable

ILLEGAL_FUNCTION, ILLEGAL_ADDRESS, ILLEGAL_VALUE = 1, 2, 3


class ModbusSlave:
    """``registers``: address -> value (FC03 and FC04 read the same bank); ``writable``: addresses a
    client may write; ``on_write(address, values)`` is called after a write is applied."""

    def __init__(self, device_id: int, registers: dict[int, int], writable: set[int] | None = None,
                 on_write: Callable[[int, list[int]], None] | None = None) -> None:
        self.device_id = device_id
        self.registers = registers
        self.writable = writable or set()
        self.on_write = on_write
        self.requests = 0
        self.exceptions = 0

    def handle(self, unit: int, pdu: bytes) -> bytes | None:
        """The response PDU, or None when the request is not addressed to this device."""
        if unit != self.device_id or not pdu:
            return None
        self.requests += 1
        fc = pdu[0]
        try:
            if fc in (3, 4):
                addr, qty = struct.unpack_from(">HH", pdu, 1)
                if not 1 <= qty <= 125:
                    return self._exception(fc, ILLEGAL_VALUE)
                regs = self.registers
                if any(a not in regs for a in range(addr, addr + qty)):
                    return self._exception(fc, ILLEGAL_ADDRESS)
                return struct.pack(f">BB{qty}H", fc, 2 * qty, *(regs[a] for a in range(addr, addr + qty)))
            if fc == 6:
                addr, value = struct.unpack_from(">HH", pdu, 1)
                return pdu[:5] if self._write(addr, [value]) else self._exception(fc, ILLEGAL_ADDRESS)
            if fc == 16:
                addr, qty, count = struct.unpack_from(">HHB", pdu, 1)
                if not 1 <= qty <= 123 or count != 2 * qty or len(pdu) != 6 + count:
                    return self._exception(fc, ILLEGAL_VALUE)
                values = list(struct.unpack_from(f">{qty}H", pdu, 6))
                return pdu[:5] if self._write(addr, values) else self._exception(fc, ILLEGAL_ADDRESS)
        except struct.error:
            return self._exception(fc, ILLEGAL_VALUE)
        return self._exception(fc, ILLEGAL_FUNCTION)

    def _write(self, addr: int, values: list[int]) -> bool:
        if any(a not in self.writable for a in range(addr, addr + len(values))):
            return False
        for i, v in enumerate(values):
            self.registers[addr + i] = v
        if self.on_write is not None:
            self.on_write(addr, values)
        return True

    def _exception(self, fc: int, code: int) -> bytes:
        self.exceptions += 1
        return bytes([(fc | 0x80) & 0xFF, code])
