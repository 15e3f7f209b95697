"""Vendor libraries that print from C++ (ur_rtde's receive thread writes ``RTDEReceiveInterface boost
system Exception: (asio.misc:2) End of file`` to ``std::cerr`` when a controller drops the link) reach
the user as one clear line each, counted, instead of their raw text. Python cannot catch those: the
process's stderr (file descriptor 2) goes through a pipe while a run lasts, known lines are
rewritten, every other line passes unchanged.
"""
from __future__ import annotations

import os
import re
import threading
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager

# (pattern, what the user reads; {what} is the library's own reason)
VENDOR_LINES: tuple[tuple[re.Pattern[str], str], ...] = (
    (re.compile(r"RTDEReceiveInterface boost system Exception: \([^)]*\) (?P<what>.*)"),
     "ur_rtde: the controller's RTDE stream dropped ({what}); the arm adapter reconnects"),
    (re.compile(r"RTDEControlInterface.*Exception: (?P<what>.*)"),
     "ur_rtde: the RTDE control link failed ({what})"),
)


class VendorStderr:
    """Counts of the vendor lines rewritten (by the line the user read) while the block ran."""

    def __init__(self) -> None:
        self.counts: Counter[str] = Counter()


def translate(line: str) -> tuple[str, bool]:
    """``line`` as the user should read it, and whether it was a vendor line."""
    for pattern, says in VENDOR_LINES:
        m = pattern.search(line)
        if m is not None:
            return says.format(what=m["what"].strip()), True
    return line, False


@contextmanager
def vendor_stderr() -> Iterator[VendorStderr]:
    """Rewrite the vendor lines on file descriptor 2 while the block runs (nothing else changes)."""
    seen = VendorStderr()
    try:
        saved = os.dup(2)
        read_fd, write_fd = os.pipe()
    except OSError:  # no descriptor 2 to take over (an embedding host): leave it alone
        yield seen
        return
    os.dup2(write_fd, 2)
    os.close(write_fd)
    pump = threading.Thread(target=_pump, args=(read_fd, saved, seen), name="vendor-stderr", daemon=True)
    pump.start()
    try:
        yield seen
    finally:
        os.dup2(saved, 2)  # the pipe's last writer closes: the pump reads its end and stops
        pump.join(2.0)
        os.close(saved)


def _pump(read_fd: int, out_fd: int, seen: VendorStderr) -> None:
    buf = b""
    with os.fdopen(read_fd, "rb", buffering=0) as src:
        while chunk := src.read(65536):
            buf += chunk
            *lines, buf = buf.split(b"\n")
            for raw in lines:
                text, vendor = translate(raw.decode("utf-8", "replace"))
                if vendor:
                    seen.counts[text] += 1
                os.write(out_fd, (text + "\n").encode())
        if buf:
            os.write(out_fd, buf)
