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


# written through the pipe when the block ends: what came before it has been passed on once the pump reads it
MARK = b"\x00ftc-vendor-stderr-end\x00"
MARK_WAIT_S = 2.0


@contextmanager
def vendor_stderr() -> Iterator[VendorStderr]:
    """Rewrite the vendor lines on file descriptor 2 while the block runs (nothing else changes).

    The block's end does not wait for the pipe to close: the processes started in it (a world, emulators,
    multiprocessing's resource tracker) hold its write end until they exit, some after this process's last
    line. It writes a mark through the pipe and waits until the pump has passed on everything before it; the
    pump then goes on passing on what those processes still write, until they are gone."""
    seen = VendorStderr()
    try:
        saved = os.dup(2)
        read_fd, write_fd = os.pipe()
    except OSError:  # no descriptor 2 to take over (an embedding host): leave it alone
        yield seen
        return
    os.dup2(write_fd, 2)
    marked = threading.Event()
    pump = threading.Thread(target=_pump, args=(read_fd, saved, seen, marked), name="vendor-stderr", daemon=True)
    pump.start()
    try:
        yield seen
    finally:
        os.dup2(saved, 2)
        os.write(write_fd, MARK)  # a write to a pipe this short is never split by another writer's
        os.close(write_fd)
        marked.wait(MARK_WAIT_S)


def _pump(read_fd: int, out_fd: int, seen: VendorStderr, marked: threading.Event) -> None:
    """Pass the pipe's lines on to ``out_fd`` (the real stderr), rewritten, until every writer has closed it."""
    buf = b""
    with os.fdopen(read_fd, "rb", buffering=0) as src, os.fdopen(out_fd, "wb", buffering=0) as out:
        while chunk := src.read(65536):
            buf += chunk
            if MARK in buf:
                before, buf = buf.split(MARK, 1)
                _pass_on(before + b"\n" if before and not before.endswith(b"\n") else before, out, seen)
                marked.set()
            *lines, buf = buf.split(b"\n")
            _pass_on(b"".join(x + b"\n" for x in lines), out, seen)
        if buf:
            out.write(buf)
    marked.set()


def _pass_on(text: bytes, out, seen: VendorStderr) -> None:
    """Whole lines (each ending in a newline), rewritten where a vendor's."""
    for raw in text.split(b"\n")[:-1]:
        line, vendor = translate(raw.decode("utf-8", "replace"))
        if vendor:
            seen.counts[line] += 1
        out.write((line + "\n").encode())
