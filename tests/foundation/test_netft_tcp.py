"""The Net F/T TCP interface's codec (port 49151): the documented byte layouts, written out byte by byte as
ATI's manual fixes them, and fuzzed: random bytes give only typed errors."""
from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ftc_hw.codecs import netft_pages as pages
from ftc_hw.codecs import netft_tcp as tcp
from ftc_hw.codecs.errors import CodecError, FrameFormatError
from ftc_hw.codecs.netft_rdt import Calibration

FUZZ = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def test_commands_are_twenty_bytes_as_the_manual_draws_them():
    assert tcp.encode_command(tcp.ReadCalInfo()) == b"\x01" + bytes(19)  # what netft_utils' ROS 2 driver sends
    assert tcp.encode_command(tcp.ReadFT(0x8001, 0x0003)) == b"\x00" + bytes(15) + b"\x80\x01\x00\x03"
    assert tcp.encode_command(tcp.WriteTransform(3, 1, (100, -100, 0, 9000, 0, -1))) == (
        b"\x02\x03\x01" + b"\x00\x64\xff\x9c\x00\x00\x23\x28\x00\x00\xff\xff" + bytes(5))
    assert tcp.encode_command(tcp.WriteThreshold(31, 5, 7, -1, -2)) == b"\x03\x1f\x05\x07\xff\xff\xfe" + bytes(13)
    for cmd in (tcp.ReadCalInfo(), tcp.ReadFT(1, 2), tcp.WriteTransform(5, 2, (1, 2, 3, 4, 5, 6)),
                tcp.WriteThreshold(0, 0, 0, 1, 32767)):
        assert tcp.decode_command(tcp.encode_command(cmd)) == cmd
    assert tcp.ReadFT(0, 1).bias and not tcp.ReadFT(0, 1).clear_latch and tcp.ReadFT(0, 2).clear_latch


def test_replies_begin_with_0x1234_and_have_the_documented_layouts():
    info = tcp.CalInfo(2, 3, 1_000_000, 1_000_000, (15260, 15260, 15260, 92, 92, 92))
    data = tcp.encode_cal_info(info)
    assert data == (b"\x12\x34\x02\x03" + b"\x00\x0f\x42\x40" * 2 + b"\x3b\x9c" * 3 + b"\x00\x5c" * 3)
    assert len(data) == 24 and tcp.decode_cal_info(data) == info
    ft = tcp.encode_ft_reply(tcp.FTReply(0x8000, (1, -1, 32767, -32768, 0, 256)))
    assert ft == b"\x12\x34\x80\x00\x00\x01\xff\xff\x7f\xff\x80\x00\x00\x00\x01\x00" and len(ft) == 16
    assert tcp.decode_ft_reply(ft) == tcp.FTReply(0x8000, (1, -1, 32767, -32768, 0, 256))
    assert tcp.encode_write_reply(2, 1) == b"\x12\x34\x02\x01" and tcp.decode_write_reply(b"\x12\x34\x03\x00") == (3, 0)


def test_the_calibration_info_of_a_box_and_its_sixteen_bit_values():
    cal = Calibration(100_000, 1_000_000, "N", "Nm")
    info = tcp.cal_info(cal, (660.0, 660.0, 1980.0, 60.0, 60.0, 60.0))
    assert (info.force_units, info.torque_units, info.counts_per_force, info.counts_per_torque) == (2, 3, 100_000,
                                                                                                      1_000_000)
    assert all(r * c / s <= 32767 for r, c, s in zip((660, 660, 1980, 60, 60, 60), (1e5,) * 3 + (1e6,) * 3,
                                                      info.scale_factors, strict=True))
    assert info.calibration().scale == cal.scale  # the same counts per unit as the pages
    assert tcp.cal_info(Calibration(1, 1, "N", "N-m"), (1,) * 6).torque_units == 3  # the pages' spelling too
    reply = tcp.ft_reply((2014, -2015, 10**9, -10**9, 0, 7), (2014, 2014, 2014, 1, 1, 1), status=0x8000_0021)
    assert reply == tcp.FTReply(0x8000, (1, -1, 32767, -32768, 0, 7))  # rounded, clamped; the upper 16 status bits
    with pytest.raises(FrameFormatError):
        tcp.cal_info(Calibration(1.5, 1, "N", "Nm"), (1,) * 6)  # counts per unit not a uint32


@pytest.mark.parametrize("data", [
    b"", b"\x01" + bytes(18), b"\x01" + bytes(20),  # not 20 bytes
    b"\x04" + bytes(19), b"\xff" * 20,  # unknown codes
])
def test_bad_commands_raise_typed_errors(data):
    with pytest.raises(tcp.TcpCommandError) as err:
        tcp.decode_command(data)
    assert err.value.command is None


@pytest.mark.parametrize("data", [
    b"\x02\x00\x01" + bytes(17), b"\x02\x03\x03" + bytes(17),  # WRITETRANSFORM unit codes out of range
    b"\x03\x20\x00\x00\x01" + bytes(15), b"\x03\x00\x06\x00\x01" + bytes(15), b"\x03\x00\x00\x00\x00" + bytes(15),
])
def test_writes_out_of_range_name_their_command(data):
    with pytest.raises(tcp.TcpCommandError) as err:
        tcp.decode_command(data)
    assert err.value.command == data[0]


@pytest.mark.parametrize("decode,data", [
    (tcp.decode_cal_info, b"\x12\x34\x02\x03" + bytes(19)),  # short
    (tcp.decode_cal_info, b"\x43\x21\x02\x03" + b"\x00\x00\x00\x01" * 2 + b"\x00\x01" * 6),  # header
    (tcp.decode_cal_info, b"\x12\x34\x07\x03" + b"\x00\x00\x00\x01" * 2 + b"\x00\x01" * 6),  # force unit code
    (tcp.decode_cal_info, b"\x12\x34\x02\x03" + bytes(4) + b"\x00\x00\x00\x01" + b"\x00\x01" * 6),  # zero cpf
    (tcp.decode_cal_info, b"\x12\x34\x02\x03" + b"\x00\x00\x00\x01" * 2 + b"\x00\x01" * 5 + bytes(2)),  # zero factor
    (tcp.decode_ft_reply, b"\x12\x34" + bytes(13)), (tcp.decode_write_reply, b"\x12\x35\x02\x00"),
])
def test_bad_replies_raise_frame_format_errors(decode, data):
    with pytest.raises(FrameFormatError):
        decode(data)


@FUZZ
@given(data=st.one_of(st.binary(max_size=40), st.binary(min_size=20, max_size=20),
                      st.builds(lambda c, rest: bytes([c]) + rest, st.integers(0, 5), st.binary(min_size=19,
                                                                                               max_size=19))))
def test_random_bytes_give_only_typed_errors(data):
    for decode in (tcp.decode_command, tcp.decode_cal_info, tcp.decode_ft_reply, tcp.decode_write_reply):
        try:
            out = decode(data)
        except CodecError:
            continue
        if decode is tcp.decode_command:
            assert tcp.decode_command(tcp.encode_command(out)) == out  # re-encodes (the reserved bytes zeroed)
        if decode is tcp.decode_cal_info:
            assert tcp.encode_cal_info(out) == data
            out.calibration()


def test_the_box_read_from_its_pages_and_readcalinfo():
    """Without the calibration page, READCALINFO's counts are taken (and checked against the configuration's);
    the calibration page, when there, comes first."""
    cal = Calibration(100_000, 1_000_000, "N", "Nm", 7000.0, 10)
    config = pages.config_page(cal, pages.BoxInfo(), index=0)
    info = tcp.cal_info(cal, pages.BoxInfo().max_range)
    box = pages.read_box(config, None, info.calibration(), "TCP 49151 READCALINFO")
    assert box.source == "TCP 49151 READCALINFO countsPerForce/countsPerTorque"
    assert box.calibration == cal and box.calibration.rdt_rate_hz == 7000.0
    assert pages.read_box(config, pages.calibration_page(cal, pages.BoxInfo()), info.calibration()).source == (
        "/netftcalapi.xml calcpf/calcpt")
    other = tcp.CalInfo(2, 3, 1_000_000, 1_000_000, info.scale_factors).calibration()
    with pytest.raises(pages.CalibrationError, match="cfgcpf: .*READCALINFO"):
        pages.read_box(config, None, other)
