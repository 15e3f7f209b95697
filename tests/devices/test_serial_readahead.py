"""``readahead://<port>`` (ftc_hw.devices.serial_urls): the port read through a buffer, for python-can's
byte-by-byte serial parser. Same bytes in the same order as written, however they are split;
timeouts, a reset and a vanished device as on the plain port."""
from __future__ import annotations

import contextlib
import os
import time

import pytest
import serial
from hypothesis import given, settings
from hypothesis import strategies as st

from ftc_hw.devices import serial_urls

pytestmark = pytest.mark.realtime  # against the wall clock: ./run-tests runs it alone, after the others


@pytest.fixture
def pty_port():
    master, slave = os.openpty()
    name = os.ttyname(slave)
    yield master, name
    for fd in (master, slave):
        with contextlib.suppress(OSError):
            os.close(fd)


def open_port(name: str, timeout: float = 0.2) -> serial.Serial:
    serial_urls.register()
    s = serial.serial_for_url(serial_urls.readahead_url(name), baudrate=115200, timeout=timeout)
    s.reset_input_buffer()
    return s


def make_raw(name: str) -> None:
    import tty

    fd = os.open(name, os.O_RDWR | os.O_NOCTTY)
    tty.setraw(fd)
    os.close(fd)


@settings(max_examples=25, deadline=None)
@given(data=st.binary(min_size=1, max_size=600), writes=st.lists(st.integers(1, 64), min_size=1, max_size=20),
       reads=st.lists(st.integers(1, 9), min_size=1, max_size=40))
def test_the_bytes_come_back_in_order_however_split(data, writes, reads):
    master, slave = os.openpty()
    name = os.ttyname(slave)
    try:
        make_raw(name)
        with open_port(name, timeout=0.05) as port:
            assert type(port).__module__ == "ftc_hw.devices.serial_urls.protocol_readahead"
            i = 0
            k = 0
            while i < len(data):
                n = writes[k % len(writes)]
                os.write(master, data[i:i + n])
                i += n
                k += 1
            got = bytearray()
            k = 0
            while len(got) < len(data):
                chunk = port.read(reads[k % len(reads)])
                assert chunk, "timed out with bytes still to come"
                got += chunk
                k += 1
            assert bytes(got) == data
            assert port.read(1) == b""  # nothing more: the timeout, an empty read
    finally:
        os.close(master)
        os.close(slave)


def test_a_read_waits_for_the_rest_until_its_timeout(pty_port):
    master, name = pty_port
    make_raw(name)
    with open_port(name, timeout=0.2) as port:
        os.write(master, b"\xaa\x01")
        assert port.read(1) == b"\xaa"
        assert port.in_waiting >= 1  # the buffered byte counts
        t0 = time.monotonic()
        assert port.read(4) == b"\x01"  # only one byte came: after the timeout
        assert time.monotonic() - t0 >= 0.15
        os.write(master, b"xyz")
        time.sleep(0.05)
        assert port.read(1) == b"x"
        port.reset_input_buffer()  # drops what was read ahead too
        assert port.in_waiting == 0
        assert port.read(1) == b""


def test_a_vanished_device_is_an_error_not_an_empty_read(pty_port):
    master, name = pty_port
    make_raw(name)
    with open_port(name, timeout=1.0) as port:
        os.close(master)
        with pytest.raises(serial.SerialException):
            port.read(1)


def test_a_url_without_a_port_is_refused():
    serial_urls.register()
    with pytest.raises(serial.SerialException, match="no port"):
        serial.serial_for_url("readahead://", timeout=0.1)
