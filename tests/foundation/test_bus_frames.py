"""Frame construction: validation, conversion, immutability."""

import dataclasses

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from ftc_hw.bus import (
    ContactEvent,
    DeviceEvent,
    FrameError,
    JointFlag,
    JointFrame,
    WrenchFlag,
    WrenchFrame,
)


def wrench(**kw):
    args = {"t_host_ns": 10, "wrench": [1, 2, 3, 4, 5, 6], "source": "ft0", "seq": 0}
    args.update(kw)
    return WrenchFrame.make(**args)


def test_wrench_make_converts_to_readonly_float64_copy():
    src = np.arange(6, dtype=np.int32)
    f = wrench(wrench=src, t_device_ns=7, flags=WrenchFlag.SATURATED | WrenchFlag.SEQ_GAP)
    assert f.wrench.dtype == np.float64 and f.wrench.shape == (6,)
    assert not f.wrench.flags.writeable
    with pytest.raises(ValueError):
        f.wrench[0] = 1.0
    src[0] = 99  # the frame holds a copy
    assert f.wrench[0] == 0.0
    assert f.force.tolist() == [0, 1, 2] and f.torque.tolist() == [3, 4, 5]
    assert not f.force.flags.writeable
    assert f.t_device_ns == 7 and f.flags == WrenchFlag.SATURATED | WrenchFlag.SEQ_GAP
    assert isinstance(f.flags, WrenchFlag)


def test_frames_are_frozen():
    f = wrench()
    with pytest.raises(dataclasses.FrozenInstanceError):
        f.seq = 3  # type: ignore[misc]
    assert not hasattr(f, "__dict__")  # slots


@given(st.integers(0, 5), st.sampled_from([np.nan, np.inf, -np.inf]))
def test_non_finite_wrench_raises_frame_error(index, bad):
    values = [0.0] * 6
    values[index] = bad
    with pytest.raises(FrameError, match=rf"wrench: non-finite value\(s\) at index \[{index}\]"):
        wrench(wrench=values)


@pytest.mark.parametrize("value", [[1, 2, 3], [0] * 7, [[0] * 6], 5.0, ["a"] * 6])
def test_wrench_shape_or_type_raises_frame_error(value):
    with pytest.raises(FrameError, match="wrench"):
        wrench(wrench=value)


@pytest.mark.parametrize(
    "kw", [{"t_host_ns": 1.5}, {"seq": "3"}, {"source": ""}, {"source": 3}, {"t_device_ns": 2.0}]
)
def test_bad_header_raises_frame_error(kw):
    with pytest.raises(FrameError):
        wrench(**kw)


def test_frame_error_is_value_error():
    assert issubclass(FrameError, ValueError)


def test_joint_frame_make_validates_lengths_and_tau():
    j = JointFrame.make(5, [0.1, 0.2], [0, 0], [1.0, 2.0], source="arm", seq=1)
    assert j.n_joints == 2 and j.tau is None
    assert all(not a.flags.writeable and a.dtype == np.float64 for a in (j.q, j.qd, j.current))
    j2 = JointFrame.make(
        5, [0.1, 0.2], [0, 0], [1.0, 2.0], [3, 4], source="arm", seq=1, flags=JointFlag.SEQ_GAP
    )
    assert j2.tau.tolist() == [3.0, 4.0] and not j2.tau.flags.writeable
    assert j2.flags == JointFlag.SEQ_GAP
    with pytest.raises(FrameError, match=r"qd: expected shape \(2,\)"):
        JointFrame.make(5, [0.1, 0.2], [0, 0, 0], [1.0, 2.0], source="arm", seq=1)
    with pytest.raises(FrameError, match="tau"):
        JointFrame.make(5, [0.1, 0.2], [0, 0], [1.0, 2.0], [1.0], source="arm", seq=1)
    with pytest.raises(FrameError, match="current: non-finite"):
        JointFrame.make(5, [0.1, 0.2], [0, 0], [1.0, np.nan], source="arm", seq=1)
    with pytest.raises(FrameError, match="at least one joint"):
        JointFrame.make(5, [], [], [], source="arm", seq=1)


def test_contact_event_make():
    c = ContactEvent.make(
        3, "onset", "link4", [0.1, 0.2, 0.3], [1, 0, 0], [0.01, 0.01, 0.02], flags=["weak"], probability=0.7
    )
    assert c.kind == "onset" and c.flags == ("weak",) and c.probability == 0.7
    assert not c.point.flags.writeable and c.force.tolist() == [1.0, 0.0, 0.0]
    with pytest.raises(FrameError, match="kind"):
        ContactEvent.make(3, "start", "link4", [0, 0, 0], [0, 0, 0])  # type: ignore[arg-type]
    with pytest.raises(FrameError, match="probability"):
        ContactEvent.make(3, "update", "link4", [0, 0, 0], [0, 0, 0], probability=float("nan"))
    with pytest.raises(FrameError, match="point_std"):
        ContactEvent.make(3, "update", "link4", [0, 0, 0], [0, 0, 0], [0, -1, 0])
    with pytest.raises(FrameError, match="point: non-finite"):
        ContactEvent.make(3, "offset", "link4", [0, np.inf, 0], [0, 0, 0])


def test_device_event_make():
    counters = {"errors": 2}
    e = DeviceEvent.make(3, "ft0", "error", "boom", counters)
    counters["errors"] = 5
    assert e.counters == {"errors": 2}
    with pytest.raises(TypeError):
        e.counters["errors"] = 1  # type: ignore[index]
    assert DeviceEvent.make(3, "ft0", "connect").counters == {}
    with pytest.raises(FrameError, match="kind"):
        DeviceEvent.make(3, "ft0", "exploded")  # type: ignore[arg-type]
