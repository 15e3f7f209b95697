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


def _received(bus_class, name: str, master: int, data: bytes, limit: int = 400) -> list:
    """What ``bus.recv`` gives for ``data`` until the line is quiet: each message's fields, or the
    exception's type (the bus opened first: opening a port flushes its input)."""
    out = []
    bus = bus_class(channel=serial_urls.readahead_url(name), baudrate=115200, timeout=0.1)
    try:
        os.write(master, data)
        time.sleep(0.01)
        for _ in range(limit):
            try:
                msg = bus.recv(0.1)
            except Exception as exc:  # noqa: BLE001 - the exception's type is what is compared
                out.append(type(exc).__name__)
                continue
            if msg is None:  # a skipped byte, or the line is quiet
                out.append(None)
                if not bus._ser.in_waiting:
                    break
                continue
            out.append((msg.timestamp, msg.arbitration_id, msg.dlc, bytes(msg.data), msg.is_extended_id,
                        msg.is_error_frame, msg.is_remote_frame))
    finally:
        bus.shutdown()
    return out


_FRAME = st.builds(lambda ts, dlc, aid, data, end: (b"\xaa" + ts.to_bytes(4, "little") + bytes([dlc])
                                                    + aid.to_bytes(4, "little") + data[:dlc] + end),
                   st.integers(0, 2**32 - 1), st.integers(0, 10), st.integers(0, 2**32 - 1), st.binary(min_size=10,
                   max_size=10), st.sampled_from([b"\xbb", b"\xbb", b"\xbb", b"\x00"]))


@settings(max_examples=20, deadline=None)
@given(parts=st.lists(st.one_of(_FRAME, _FRAME, st.binary(min_size=1, max_size=5)), min_size=1, max_size=12))
def test_whole_frames_parsed_at_once_give_what_python_can_gives(parts):
    """ftc_hw.devices.can_serial's fast path against python-can's own parser on the same bytes: valid
    frames of every DLC and id, bad DLCs, bad end bytes, noise between them."""
    from can.interfaces.serial.serial_can import SerialBus

    from ftc_hw.devices.can_serial import ReadAheadSerialBus

    data = b"".join(parts)
    got = {}
    for bus_class in (SerialBus, ReadAheadSerialBus):
        master, slave = os.openpty()
        name = os.ttyname(slave)
        try:
            make_raw(name)
            serial_urls.register()
            got[bus_class.__name__] = _received(bus_class, name, master, data)
        finally:
            os.close(master)
            os.close(slave)
    assert got["ReadAheadSerialBus"] == got["SerialBus"]
    assert got["SerialBus"]  # the bytes were read: messages, errors or skipped bytes
