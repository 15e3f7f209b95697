"""pyserial URL handlers of our own (pyserial's ``protocol_handler_packages`` extension point):
``readahead://<port>`` is the port read through a buffer (:mod:`.protocol_readahead`)."""
from __future__ import annotations

import serial

from .protocol_readahead import PREFIX as READAHEAD

PACKAGE = __name__


def register() -> None:
    """Let ``serial.serial_for_url`` (and so python-can's serial interface) open our URLs (idempotent)."""
    if PACKAGE not in serial.protocol_handler_packages:
        serial.protocol_handler_packages.append(PACKAGE)


def readahead_url(port: str) -> str:
    return f"{READAHEAD}{port}"
