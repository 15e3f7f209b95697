"""Interpolation and hold of joint/wrench frames, used by :meth:`Bus.sample_at`."""

from __future__ import annotations

from typing import Any

import numpy as np

from .frames import JointFlag, JointFrame, WrenchFlag, WrenchFrame

__all__ = ["hold", "interpolate"]


def _lerp(x0: np.ndarray, x1: np.ndarray, w: float) -> np.ndarray:
    out = x1 - x0
    out *= w
    out += x0
    out.flags.writeable = False
    return out


def _flags(a: Any, b: Any, extra: JointFlag | WrenchFlag) -> Any:
    # IntFlag "|" goes through the enum machinery (~0.5 us): skip it in the common all-clear case.
    return extra if not (a.flags or b.flags) else a.flags | b.flags | extra


def interpolate(a: Any, b: Any, t_ns: int) -> JointFrame | WrenchFrame:
    """Linear interpolation between frames ``a`` and ``b`` (same type, ``a`` older) at host time ``t_ns``.

    Array fields and ``t_device_ns`` (when both have one) are interpolated; ``tau`` only when both
    have it. The result carries ``a.seq``, both frames' flags and ``INTERPOLATED``.
    """
    w = (t_ns - a.t_host_ns) / (b.t_host_ns - a.t_host_ns)
    t_dev = None
    if a.t_device_ns is not None and b.t_device_ns is not None:
        t_dev = a.t_device_ns + round(w * (b.t_device_ns - a.t_device_ns))
    if isinstance(a, JointFrame):
        tau = None if a.tau is None or b.tau is None else _lerp(a.tau, b.tau, w)
        return JointFrame(
            t_ns,
            t_dev,
            a.seq,
            a.source,
            _lerp(a.q, b.q, w),
            _lerp(a.qd, b.qd, w),
            _lerp(a.current, b.current, w),
            tau,
            _flags(a, b, JointFlag.INTERPOLATED),
        )
    if isinstance(a, WrenchFrame):
        return WrenchFrame(
            t_ns,
            t_dev,
            a.seq,
            a.source,
            _lerp(a.wrench, b.wrench, w),
            _flags(a, b, WrenchFlag.INTERPOLATED),
        )
    raise TypeError(f"sample_at works on JointFrame and WrenchFrame topics, got {type(a).__name__}")


def hold(a: Any, t_ns: int) -> JointFrame | WrenchFrame:
    """Zero-order hold of frame ``a`` at host time ``t_ns``: ``t_device_ns=None``, flag ``HELD``."""
    if isinstance(a, JointFrame):
        return JointFrame(t_ns, None, a.seq, a.source, a.q, a.qd, a.current, a.tau, a.flags | JointFlag.HELD)
    if isinstance(a, WrenchFrame):
        return WrenchFrame(t_ns, None, a.seq, a.source, a.wrench, a.flags | WrenchFlag.HELD)
    raise TypeError(f"sample_at works on JointFrame and WrenchFrame topics, got {type(a).__name__}")
