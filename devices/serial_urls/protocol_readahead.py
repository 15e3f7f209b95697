"""``readahead://<port>``: a serial port whose reads are served from a buffer filled by one system
call per burst of bytes.

python-can's serial interface takes each CAN frame in six ``read()`` calls of 1-4 bytes; on a plain
port every one is a ``select`` and a ``read`` system call and gives up the interpreter twice, which
at 2000 frames a second made the reader wait behind the monitor's other threads. Here a read takes
what is buffered and, when that is not enough, waits (up to the port's timeout) for more and reads
everything the driver holds. Timeouts, cancel_read and a vanished device behave as on the plain port.
"""
from __future__ import annotations

import errno
import os
import select

import serial
from serial.serialutil import PortNotOpenError, SerialException, Timeout

PREFIX = "readahead://"
CHUNK = 4096
_RETRY = (errno.EAGAIN, errno.EALREADY, errno.EWOULDBLOCK, errno.EINPROGRESS, errno.EINTR)


class Serial(serial.Serial):
    """The platform's serial port with buffered reads (POSIX: it needs ``fd`` and the abort pipe)."""

    def __init__(self, *args, **kwargs) -> None:
        self._ahead = bytearray()
        super().__init__(*args, **kwargs)

    def open(self) -> None:
        self._ahead.clear()
        super().open()

    @property
    def in_waiting(self) -> int:
        return len(self._ahead) + super().in_waiting

    def reset_input_buffer(self) -> None:
        self._ahead.clear()
        super().reset_input_buffer()

    def read(self, size: int = 1) -> bytes:
        if not self.is_open:
            raise PortNotOpenError()
        ahead = self._ahead
        if len(ahead) < size:
            timeout = Timeout(self._timeout)
            while len(ahead) < size:
                try:
                    ready, _, _ = select.select([self.fd, self.pipe_abort_read_r], [], [], timeout.time_left())
                    if self.pipe_abort_read_r in ready:  # cancel_read()
                        os.read(self.pipe_abort_read_r, 1000)
                        break
                    if not ready:
                        break  # the timeout
                    chunk = os.read(self.fd, CHUNK)
                except OSError as exc:
                    if exc.errno not in _RETRY:
                        raise SerialException(f"read failed: {exc}") from exc
                else:
                    if not chunk:  # readable but nothing there: the device is gone
                        raise SerialException("the port signalled data but gave none: the device is gone "
                                              "(or another process reads the port)")
                    ahead += chunk
                if timeout.expired():
                    break
        n = min(size, len(ahead))
        out = bytes(ahead[:n])
        del ahead[:n]
        return out


def serial_class_for_url(url: str) -> tuple[str, type[Serial]]:
    """pyserial's hook: the real port behind the URL, and the class that opens it."""
    if not url.lower().startswith(PREFIX):
        raise SerialException(f"expected a {PREFIX}<port> URL, got {url!r}")
    port = url[len(PREFIX):]
    if not port:
        raise SerialException(f"{url!r}: no port after {PREFIX}")
    return port, Serial
