"""libfranka's protocol (FCI) codec: the struct sizes libfranka checks, round trips, fuzz (only typed
errors escape)."""
from __future__ import annotations

import contextlib
import struct

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ftc_hw.codecs import CodecError
from ftc_hw.codecs import franka as F

FUZZ = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
PROTOS = st.sampled_from([F.V5, F.V10])


def test_struct_sizes_are_libfrankas():
    # version 5: uint64, 284 doubles, 2 enums, 2 x 41 bools, mode, a double; version 10 the same in
    # float32 plus 2 x 18 accelerometer floats (both measured against the clients: tests/sim)
    assert F.V5.state_size == 8 + 284 * 8 + 2 + 82 + 1 + 8 == 2373
    assert F.V10.state_size == 8 + (284 + 36) * 4 + 2 + 82 + 1 + 4 == 1377
    assert (F.V5.command_size, F.V10.command_size) == (370, 371)
    assert F.V5.state.names.index("tau_J") < F.V5.state.names.index("q")  # libfranka's order
    assert F.V5.commands["AutomaticErrorRecovery"] == 12 and F.V10.commands["AutomaticErrorRecovery"] == 10
    assert F.V10.commands["GetRobotModel"] == 11 and "LoadModelLibrary" not in F.V10.commands


def test_connect_round_trip_is_little_endian_and_packed():
    data = F.encode_connect(F.V10, 7, 50123)
    assert data == struct.pack("<IIIHH", 0, 7, 16, 10, 50123)
    header = F.decode_header(data)
    assert header == F.Header(0, 7, 16) and F.check_request(F.V10, header) == "Connect"
    assert F.decode_connect(data[12:]) == (10, 50123)
    reply = F.encode_connect_response(header, F.SUCCESS, 10)
    assert reply == struct.pack("<IIIBH", 0, 7, 15, 0, 10)
    assert F.decode_response(reply) == (F.Header(0, 7, 15), 0, b"\x0a\x00")


@pytest.mark.parametrize("proto", [F.V5, F.V10], ids=["v5", "v10"])
def test_state_round_trip(proto):
    st_ = F.new_state(proto)
    rng = np.random.default_rng(1)
    st_["message_id"], st_["robot_mode"] = 123456789, F.MODE_MOVE
    q, tau = rng.normal(size=7), rng.normal(size=7) * 50
    st_["q"], st_["tau_J"] = q, tau
    st_["O_T_EE"] = F.column_major(np.arange(16.0).reshape(4, 4))
    back = F.decode_state(proto, F.encode_state(st_))
    tol = 1e-15 if proto is F.V5 else 1e-5  # float32 in version 10
    assert back["message_id"] == 123456789 and back["robot_mode"] == F.MODE_MOVE
    assert np.allclose(back["q"], q, rtol=tol, atol=tol) and np.allclose(back["tau_J"], tau, rtol=tol, atol=tol)
    assert back["O_T_EE"][4] == 1.0  # column-major: element (0, 1) is the fifth value


@FUZZ
@given(proto=PROTOS, data=st.binary(max_size=2500))
def test_random_bytes_raise_only_typed_errors(proto, data):
    for decode in (lambda d: F.decode_state(proto, d), lambda d: F.decode_command(proto, d), F.decode_response,
                   F.decode_connect, lambda d: F.check_request(proto, F.decode_header(d))):
        with contextlib.suppress(CodecError):
            decode(data)


@FUZZ
@given(proto=PROTOS, cut=st.integers(-40, 40).filter(bool))
def test_a_state_of_any_other_size_is_refused(proto, cut):
    data = F.encode_state(F.new_state(proto))
    bad = data[:cut] if cut < 0 else data + bytes(cut)
    with pytest.raises(F.FrankaProtocolError):
        F.decode_state(proto, bad)


@FUZZ
@given(proto=PROTOS, command=st.integers(0, 20), size=st.integers(0, 400), command_id=st.integers(0, 2**32 - 1))
def test_requests_of_unknown_commands_or_wrong_sizes_are_typed_errors(proto, command, size, command_id):
    header = F.decode_header(struct.pack("<III", command, command_id, F.HEADER_SIZE + size))
    name = proto.names.get(command)
    want = F.REQUEST_SIZES.get(name) if name else None
    if name is not None and (want is None or want == size):
        assert F.check_request(proto, header) == name
    else:
        with pytest.raises(F.FrankaProtocolError):
            F.check_request(proto, header)


def test_a_header_shorter_than_itself_is_refused():
    with pytest.raises(F.FrankaProtocolError):
        F.decode_header(struct.pack("<III", 0, 0, 11))
    with pytest.raises(F.FrankaProtocolError):
        F.decode_header(b"\x00" * 11)


def test_a_robot_mode_outside_libfrankas_is_refused():
    st_ = F.new_state(F.V10)
    st_["robot_mode"] = len(F.ROBOT_MODES)
    with pytest.raises(F.FrankaProtocolError):
        F.decode_state(F.V10, F.encode_state(st_))
