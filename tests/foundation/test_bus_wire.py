"""The bus frames' binary format (ftc_hw.bus.wire): every frame kind round-trips bit for bit; a
message of another major version, a foreign or a corrupt one is a typed error, never a wrong frame;
a newer minor version's appended fields are skipped."""
from __future__ import annotations

import struct

import numpy as np
import pytest

from ftc_hw.bus import ContactEvent, DeviceEvent, JointFrame, WrenchFrame
from ftc_hw.bus.wire import (
    MAJOR,
    MINOR,
    WireError,
    WireForeignError,
    WireVersionError,
    decode,
    encode,
)

FRAMES = [
    WrenchFrame.make(123_456_789, [0.1, -2.5, 9.81, 1e-9, -0.3, 1e3], source="ft", seq=2**40, flags=3),
    WrenchFrame.make(5, np.zeros(6), source="ft-can", seq=0, t_device_ns=-7),
    JointFrame.make(124, [0.1, -0.2, 3.1], [1.0, 2.0, -3.0], [0.5, 0.6, 0.7], [0.0, 1.5, -2.5], source="arm", seq=7,
                    t_device_ns=99, flags=4),
    JointFrame.make(125, [0.3], [0.0], [0.0], source="servo", seq=1),
    ContactEvent.make(126, "update", "wrist_3", [0.1, 0.2, 0.3], [1.0, 2.0, 3.0], [0.01, 0.01, 0.02],
                      flags=("ambiguous", "impact"), probability=0.7, contact_id=3, duration_s=0.2, peak_force=10.0,
                      impulse=1.5),
    ContactEvent.make(126, "offset", "forearm", [0.1, 0.2, 0.3], [1.0, 2.0, 3.0], [0.01, 0.01, 0.02],
                      contact_class="quasi_static", p_quasi_static=0.97, intent="impact", p_guidance=0.01,
                      class_features={"held_s": 2.1, "v_onset_mps": -0.03}),
    DeviceEvent.make(127, "ft", "stale", "no frame on wrench/ft for 0.052 s", {"frames": 10.0, "timeout_s": 0.05}),
    DeviceEvent.make(128, "bus", "connect"),
]


def _same(a, b) -> bool:
    if type(a) is not type(b):
        return False
    for k in a.__slots__:
        x, y = getattr(a, k), getattr(b, k)
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            if x is None or y is None or x.tobytes() != y.tobytes():
                return False
        elif x != y:
            return False
    return True


@pytest.mark.parametrize("frame", FRAMES, ids=lambda f: type(f).__name__)
def test_every_frame_kind_round_trips_bit_for_bit(frame):
    data = encode(frame)
    back = decode(data)
    assert _same(frame, back), (frame, back)
    for arr in (getattr(back, k) for k in back.__slots__):
        if isinstance(arr, np.ndarray):
            assert arr.dtype == np.float64 and not arr.flags.writeable
    # compact: a wrench is 84 bytes (JSON in the recordings is about 250)
    if isinstance(frame, WrenchFrame):
        assert len(data) == 5 + 28 + 1 + len(frame.source) + 48


def test_another_major_version_is_a_version_error():
    data = bytearray(encode(FRAMES[0]))
    data[2] = MAJOR + 1
    with pytest.raises(WireVersionError, match=f"this reader decodes {MAJOR}.x"):
        decode(bytes(data))


def test_a_newer_minor_versions_appended_fields_are_skipped_and_ours_must_end_exactly():
    data = bytearray(encode(FRAMES[2]))
    newer = bytes(data[:3]) + bytes([MINOR + 1]) + bytes(data[4:]) + b"\x01\x02new field"
    assert _same(decode(newer), FRAMES[2])
    with pytest.raises(WireError, match="bytes after the frame's last field"):
        decode(bytes(data) + b"\x00")


@pytest.mark.parametrize("payload", [b"", b"FT", b'{"wrench": [1, 2, 3]}', b"\x00" * 90, "héllo".encode()])
def test_foreign_payloads_are_foreign(payload):
    with pytest.raises(WireForeignError):
        decode(payload)


def test_truncated_unknown_or_non_finite_messages_are_wire_errors():
    data = encode(FRAMES[0])
    for cut in (6, 20, len(data) - 1):
        with pytest.raises(WireError, match="truncated"):
            decode(data[:cut])
    with pytest.raises(WireError, match="unknown frame kind 9"):
        decode(data[:4] + b"\x09" + data[5:])
    nan = data[:-8] + struct.pack("<d", float("nan"))
    with pytest.raises(WireError, match="non-finite"):
        decode(nan)
    bad_kind = bytearray(encode(FRAMES[4]))
    bad_kind[5 + 8] = 7  # the contact event's kind code
    with pytest.raises(WireError, match="kind code 7"):
        decode(bytes(bad_kind))
    with pytest.raises(TypeError, match="not a bus frame"):
        encode(object())


def test_a_contact_event_of_minor_version_0_decodes_unclassified():
    ev = ContactEvent.make(126, "onset", "wrist_3", [0.1, 0.2, 0.3], [1.0, 2.0, 3.0])
    data = bytearray(encode(ev))
    assert data[3] == MINOR >= 2
    # 1.0: without its limits (a byte: none) and its class (two empty names, 2 f64, 0 features: 19 bytes)
    old = bytes(data[:3]) + bytes([0]) + bytes(data[4:-20])
    back = decode(old)
    assert _same(ev, back)
    assert (back.contact_class, back.intent, back.p_quasi_static, back.p_guidance) == ("", "", 0.5, 0.5)
    assert _same(ev, decode(bytes(data[:3]) + bytes([1]) + bytes(data[4:-19])))  # 1.1: limits, no class
    with pytest.raises(WireError):  # a minor-0 message with the class's bytes after its end: not ours
        decode(bytes(data[:3]) + bytes([0]) + bytes(data[4:]))
