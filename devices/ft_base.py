"""What every F/T adapter does with a decoded sample before it reaches the bus.

:class:`FTAdapter` adds to :class:`~ftc_hw.devices.base.Adapter`: a staleness watchdog on its topic (a
``stale`` event ``stale_after`` s after the last frame, ``recovered`` on the next), sequence
tracking (device counters unwrapped; a gap flags ``SEQ_GAP`` on the first frame after it and is
counted; a repeated number is a duplicate and never published; a backwards jump is a device reset),
saturation (``SATURATED`` from the device's status bits, or any axis at the device's range), device
clocks (unwrapped to ns; a :class:`~ftc_hw.bus.ClockAligner` fed with every sample, ``CLOCK_SUSPECT``
until it is ready or when it resets) and the counters.

Frames: ``t_host_ns`` = ``time.monotonic_ns()`` when the bytes arrived; ``t_device_ns`` = the
device's clock in ns (unwrapped), None when the device sends none; ``seq`` = the device's counter
unwrapped (offset after a device reset so that it keeps increasing), or the adapter's own count.
"""
from __future__ import annotations

import time
from collections import Counter, deque
from collections.abc import Sequence
from typing import Any

import numpy as np

from ftc_hw.bus import Bus, ClockAligner, Watchdog, WrenchFlag, WrenchFrame, wrench_topic

from .base import Adapter, DeviceIOError

STATUS_SATURATION_MASK = 0x3F
STATUS_ERROR_MASK = 0x80 | 1 << 31  # the status bits of a device error (the stream formats' and CAN's)


def at_range(wrench: Sequence[float], full_scale: np.ndarray) -> bool:
    """Whether any axis of ``wrench`` (SI, 6) reached the device's full scale (6): a reading clipped there
    is a lower bound (flagged ``SATURATED``) when the device sends no saturation bits."""
    return bool(np.any(np.abs(np.asarray(wrench, dtype=float)) >= full_scale * (1 - 1e-9)))


class Unwrapper:
    """Unwraps a counter of period ``modulus``: forward steps of less than half a period are kept,
    anything else is a reset (the next value starts a new epoch)."""

    def __init__(self, modulus: int | None) -> None:
        self.modulus = modulus
        self.raw: int | None = None
        self.value = 0

    def update(self, raw: int) -> tuple[int, int | None]:
        """``(unwrapped, step)``; step is None after a reset (or for the first value)."""
        if self.raw is None or self.modulus is None:
            step = None if self.raw is None else raw - self.raw
            if step is not None and step < 0:
                step = None
            self.value = raw if step is None else self.value + step
        else:
            d = (raw - self.raw) % self.modulus
            if d < self.modulus // 2:
                step = d
                self.value += d
            else:
                step = None
                self.value = raw
        self.raw = raw
        return self.value, step


class Silence:
    """How long a stream has said nothing valid: counted once in ``timeouts`` past ``stale_after`` s, and a
    broken link (DeviceIOError, the reader reconnects) past ``silence_s`` s (None: never)."""

    def __init__(self, stale_after: float, silence_s: float | None) -> None:
        self.stale_after, self.silence_s = stale_after, silence_s
        self.last = time.monotonic()
        self.silent = False

    def heard(self, now: float) -> None:
        self.last = now
        self.silent = False

    def check(self, now: float, counters: Counter[str]) -> None:
        quiet = now - self.last
        if not self.silent and quiet > self.stale_after:
            self.silent = True
            counters["timeouts"] += 1
        if self.silence_s is not None and quiet > self.silence_s:
            raise DeviceIOError(f"no sample for {quiet:.2f} s")


class FTAdapter(Adapter):
    """Base of the F/T adapters. ``range``: the device's full scale (SI, 6 values) for saturation when
    it sends no status bits; ``seq_modulus`` / ``t_device_modulus_ns``: wrap periods of the device's
    counters; ``seq_period_ns``: derive ``t_device_ns`` from the sample counter (a counter ticking at
    the sensor rate is a clock); ``stale_after``: seconds without a frame before ``stale``."""

    kind = "ft"
    role = "ft"
    status_error_mask = STATUS_ERROR_MASK  # a kind whose status word says more sets its own

    def __init__(self, name: str, bus: Bus, *, range: Sequence[float] | None = None, stale_after: float = 0.05,
                 seq_modulus: int | None = None, t_device_modulus_ns: int | None = None,
                 seq_period_ns: int | None = None, reconnect_backoff: tuple[float, float] = (0.02, 0.25),
                 poll_timeout: float = 0.02) -> None:
        super().__init__(name, bus, reconnect_backoff=reconnect_backoff, poll_timeout=poll_timeout)
        self.topic = wrench_topic(name)
        self.range = None if range is None else np.asarray(range, dtype=float)
        self.stale_after = float(stale_after)
        self.seq_period_ns = seq_period_ns
        self.clock = ClockAligner()
        self.gaps: deque[tuple[int, int]] = deque(maxlen=100_000)  # (first missing seq, how many)
        self._seq = Unwrapper(seq_modulus)
        self._tdev = Unwrapper(t_device_modulus_ns)
        self._seq_offset = 0
        self._bus_seq = -1
        self._clock_resets = 0
        self._status_error = 0  # the error bits of the last status word (0: none)
        self.watchdog: Watchdog | None = None
        self.identity: dict[str, str] = {}

    # -- lifecycle: the watchdog lives as long as the reader -----------------------------------------
    def open(self) -> FTAdapter:
        with self._lock:
            start = self._thread is None and self.watchdog is None
            if start:
                self.watchdog = Watchdog(self.bus, {self.topic: self.stale_after},
                                         period=min(0.01, self.stale_after / 4))
        if start:
            self.watchdog.start()  # type: ignore[union-attr]
        super().open()
        return self

    def close(self) -> None:
        super().close()
        wd, self.watchdog = self.watchdog, None
        if wd is not None:
            wd.stop()

    @property
    def stale(self) -> bool:
        wd = self.watchdog
        return wd is not None and self.topic in wd.stale_topics

    def status(self) -> dict[str, Any]:
        return {**super().status(), "stale": self.stale, "identity": dict(self.identity)}

    # -- publishing ----------------------------------------------------------------------------------
    def publish_sample(self, wrench: Sequence[float], *, t_host_ns: int, seq: int | None = None,
                       t_device_ns: int | None = None, status: int | None = None) -> WrenchFrame | None:
        """Flag, count and publish one decoded sample; None when it is not published (a duplicate)."""
        c = self.counters
        flags = WrenchFlag.NONE
        derived_time = False
        if seq is not None:
            u, step = self._seq.update(seq)
            if step == 0:
                c["duplicates"] += 1
                return None
            if step is None:
                if self._bus_seq >= 0:
                    c["seq_resets"] += 1
                    self._seq_offset = self._bus_seq + 1 - u
            elif step > 1:
                flags |= WrenchFlag.SEQ_GAP
                c["seq_gaps"] += 1
                c["lost"] += step - 1
                self.gaps.append((u - step + 1 + self._seq_offset, step - 1))
            bus_seq = u + self._seq_offset
            if t_device_ns is None and self.seq_period_ns is not None:
                t_device_ns = u * self.seq_period_ns  # already unwrapped with the counter
                derived_time = True
        else:
            bus_seq = self._bus_seq + 1
        if status is not None:
            sat = status & STATUS_SATURATION_MASK
            errors = status & self.status_error_mask
            if errors or self._status_error:
                flags |= self._check_status(errors)
        elif self.range is not None:
            sat = int(at_range(wrench, self.range))
        else:
            sat = 0
        if sat:
            flags |= WrenchFlag.SATURATED
            c["saturated"] += 1
        t_dev = None
        if t_device_ns is not None:
            t_dev = t_device_ns if derived_time else self._tdev.update(t_device_ns)[0]
            self.clock.update(t_dev, t_host_ns)
            if not self.clock.ready or self.clock.resets != self._clock_resets:
                flags |= WrenchFlag.CLOCK_SUSPECT
                self._clock_resets = self.clock.resets
        frame = WrenchFrame.make(t_host_ns, wrench, source=self.name, seq=bus_seq, t_device_ns=t_dev, flags=flags)
        self._bus_seq = bus_seq
        self.bus.publish(self.topic, frame)
        c["frames"] += 1
        return frame

    def _check_status(self, errors: int) -> WrenchFlag:
        """Counts a sample whose status word reports an error and flags it; an event when the device starts
        and stops reporting errors (or reports other bits)."""
        if errors != self._status_error:
            if errors:
                self.event("error", f"status word error bits {errors:#010x}: frames flagged DEVICE_ERROR "
                           "while they are set")
            else:
                self.event("recovered", f"status word error bits clear (were {self._status_error:#010x})")
            self._status_error = errors
        if not errors:
            return WrenchFlag.NONE
        self.counters["device_errors"] += 1
        return WrenchFlag.DEVICE_ERROR
