"""A fast path for CAN messages whose signals are whole little-endian integers on byte boundaries
(the Net F/T's frames): ``struct`` instead of cantools' bit-level codec and its strict checks, about
a fifth of the time a frame (the emulator encodes four frames a sample at 1 kHz, the reader decodes
them). The values are cantools' own: each signal's conversion scales and rounds, only the packing
is struct's. A value cantools would check (outside the signal's range, or a raw value the field
cannot hold) is left to cantools (``encode`` returns None), so its errors are unchanged.
"""
from __future__ import annotations

import struct
from collections.abc import Mapping
from typing import Any

_FORMATS = {8: "b", 16: "h", 32: "i", 64: "q"}  # signed; upper case unsigned


class FastLayout:
    """One message's signals as ``(name, conversion, minimum, maximum, raw limits)`` and a struct."""

    def __init__(self, message: Any) -> None:
        self.length = message.length
        fields = sorted(message.signals, key=lambda s: s.start)
        fmt, pos = "<", 0
        self.signals = []
        for s in fields:
            code = _FORMATS[s.length]
            if s.start // 8 > pos:
                fmt += f"{s.start // 8 - pos}x"
            fmt += code if s.is_signed else code.upper()
            pos = s.start // 8 + s.length // 8
            bits = s.length - 1 if s.is_signed else s.length
            low = -(1 << bits) if s.is_signed else 0
            self.signals.append((s.name, s.conversion, s.minimum, s.maximum, low, (1 << bits) - 1))
        if pos < self.length:
            fmt += f"{self.length - pos}x"
        self.struct = struct.Struct(fmt)

    @staticmethod
    def fits(message: Any) -> bool:
        """Whether every signal of ``message`` is a plain integer field struct can pack."""
        spans = []
        for s in message.signals:
            if (s.byte_order != "little_endian" or s.is_float or s.start % 8 or s.length not in _FORMATS
                    or s.is_multiplexer or s.multiplexer_ids or s.conversion.choices):
                return False
            spans.append((s.start // 8, s.start // 8 + s.length // 8))
        spans.sort()
        return (bool(spans) and spans[-1][1] <= message.length
                and all(a[1] <= b[0] for a, b in zip(spans, spans[1:], strict=False)))

    def encode(self, values: Mapping[str, float | int]) -> bytes | None:
        """The frame's bytes, as ``message.encode(values)`` gives them; None: ask cantools."""
        if len(values) != len(self.signals):
            return None
        raws = []
        for name, conversion, minimum, maximum, low, high in self.signals:
            v = values.get(name)
            if not isinstance(v, int | float) or (minimum is not None and not minimum <= v) or (
                    maximum is not None and not v <= maximum):
                return None
            raw = conversion.numeric_scaled_to_raw(v)
            if not low <= raw <= high:
                return None
            raws.append(raw)
        return self.struct.pack(*raws)

    def decode(self, data: bytes) -> dict[str, float | int]:
        """The scaled values, as ``message.decode(data, decode_choices=False, scaling=True)`` gives
        them; ``data`` must be ``length`` bytes long."""
        raws = self.struct.unpack(data)
        return {s[0]: s[1].raw_to_scaled(raw, False) for s, raw in zip(self.signals, raws, strict=True)}
