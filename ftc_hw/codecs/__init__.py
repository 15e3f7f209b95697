"""Codecs: bytes (or registers, or CAN frames) in, samples out, and back. No I/O anywhere here."""
from .checksums import CHECKSUMS, crc16_ccitt, crc16_modbus
from .errors import ChecksumError, CodecError, FrameFormatError
from .registers import FT300_MAP, MAPS, RegisterField, RegisterMap, register_map
from .stream import (
    AXES,
    FORMATS,
    FT300_STREAM,
    FTC_1K,
    StreamField,
    StreamFormat,
    StreamParser,
    StreamSample,
    stream_format,
)

__all__ = [
    "AXES", "CHECKSUMS", "FORMATS", "FT300_MAP", "FT300_STREAM", "FTC_1K", "MAPS", "ChecksumError", "CodecError",
    "FrameFormatError", "RegisterField", "RegisterMap", "StreamField", "StreamFormat", "StreamParser",
    "StreamSample", "crc16_ccitt", "crc16_modbus", "register_map", "stream_format",
]
