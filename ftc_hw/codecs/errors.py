"""Typed codec errors. Each carries ``consumed``: how many bytes the caller should drop before trying
again (1 for a rejected candidate frame, so that a real frame starting inside it is not lost)."""
from __future__ import annotations


class CodecError(Exception):
    """Base of every error a codec raises on bad input."""

    def __init__(self, message: str, consumed: int = 1) -> None:
        super().__init__(message)
        self.consumed = consumed


class ChecksumError(CodecError):
    """A candidate frame whose checksum or CRC does not match its contents."""


class FrameFormatError(CodecError):
    """A frame with a valid checksum whose contents are impossible (bad length, NaN, unknown code)."""
