"""python-can's ``serial`` interface on a ``readahead://`` port (:mod:`ftc_hw.devices.serial_urls`), a
frame that is already whole in the port's buffer parsed in one go.

python-can 4.6.1 takes each frame in six ``read()`` calls (start byte, timestamp, DLC, id, data,
end byte): half the reader's time at 4000 frames a second. Here a whole, well-formed frame at the
head of the buffer becomes the same :class:`can.Message` python-can would make of it and consumes
the same bytes; anything else (a partial frame, noise, a bad DLC or end byte) goes to python-can's
own code, so what it returns, raises and consumes is python-can's.
"""
from __future__ import annotations

import struct

import serial
from can import CanOperationError, Message
from can.interfaces.serial.serial_can import (
    CAN_EFF_FLAG,
    CAN_ERR_FLAG,
    CAN_ID_MASK_EXT,
    CAN_ID_MASK_STD,
    CAN_RTR_FLAG,
    SerialBus,
)

from .serial_urls.protocol_readahead import Serial as ReadAheadSerial

_HEAD = struct.Struct("<xIBI")  # 0xAA, timestamp (ms), DLC, arbitration id with its flags
_START, _END, _HEAD_SIZE = 0xAA, 0xBB, 10


def whole_frame(buffer: bytearray) -> Message | None:
    """The frame at the head of ``buffer`` (consumed) when it is whole and well formed, else None
    (nothing consumed)."""
    if len(buffer) < _HEAD_SIZE + 1 or buffer[0] != _START:
        return None
    dlc = buffer[5]
    end = _HEAD_SIZE + dlc
    if dlc > 8 or len(buffer) <= end or buffer[end] != _END:
        return None
    timestamp, _, arbitration_id = _HEAD.unpack_from(buffer)
    data = bytes(buffer[_HEAD_SIZE:end])
    del buffer[:end + 1]
    extended = bool(arbitration_id & CAN_EFF_FLAG)
    return Message(timestamp=timestamp / 1000,
                   arbitration_id=arbitration_id & (CAN_ID_MASK_EXT if extended else CAN_ID_MASK_STD),
                   dlc=dlc, data=data, is_extended_id=extended, is_error_frame=bool(arbitration_id & CAN_ERR_FLAG),
                   is_remote_frame=bool(arbitration_id & CAN_RTR_FLAG))


class ReadAheadSerialBus(SerialBus):
    """``SerialBus`` whose receive takes whole frames straight from a read-ahead port's buffer."""

    def _recv_internal(self, timeout: float | None) -> tuple[Message | None, bool]:
        port = self._ser
        if isinstance(port, ReadAheadSerial):
            try:
                buffer = port.fill(1)  # waits as python-can's first read(1) would
            except serial.SerialException as error:
                raise CanOperationError("could not read from serial") from error
            if not buffer:
                return None, False  # the port's timeout, as python-can says it
            msg = whole_frame(buffer)
            if msg is not None:
                return msg, False
        return super()._recv_internal(timeout)
