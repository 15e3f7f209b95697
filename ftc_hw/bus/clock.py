"""Device-to-host clock alignment, robust to transport delay spikes.

Each sample pairs a device timestamp with the host receive time: ``t_host = h(t_device) + delay``
where ``h`` maps device time to host time (offset plus a small rate error, the skew) and
``delay >= 0``. Delays are positive and spiky but often close to a floor, so the lower envelope of
``t_host - t_device`` over a sliding window tracks ``h(t_device) - t_device + floor``:

* without skew estimation, the offset is the sliding-window minimum of ``t_host - t_device``;
* with skew estimation (default), the slope comes from the lower convex hull of per-bucket minima
  (the edge spanning the window's mean time: the linear programme of Moon, Skelly & Towsley 1999,
  applied to bucket minima so that a bucket hit only by spikes is ignored), and the intercept puts the
  line under every sample of the window.

Cost: a sample is a few deque and ring writes; every ``refit_every`` samples the fit is one pass over
the window (no sort: the window's device times never decrease, so a bucket is a run of samples),
compiled where numba is loaded (:func:`_fit_functions`): ~2-3 us a sample on average at 7 kHz
compiled, ~3.5 in numpy (it was ~20 us with the fit sorting the window).

:meth:`ClockAligner.to_host` therefore returns the host time at which a minimum-delay packet stamped
``t_device_ns`` would have arrived: true host time of the device event plus the delay floor, which
timestamps alone cannot observe (subtract it if known).

A device clock going backwards, or a sample arriving more than ``jump_ns`` *earlier* than the current
estimate allows (impossible with positive delays), resets the estimate (``resets`` counts them).

The estimate falls at once (a lower delay floor is seen) but rises no faster than ``max_skew``: a
reader that falls behind its device builds a backlog whose delay grows for seconds, and once the
window has slid past the last prompt sample its minimum rises with the backlog. Followed, that would
shift the stream's time by the backlog against the others (a compensation fed the joint state of
another moment); capped, late frames keep their true time (``capped`` counts the capped fits).
"""

from __future__ import annotations

import sys
from collections import deque

import numpy as np

__all__ = ["ClockAligner", "ClockNotReadyError"]


_KERNELS: tuple | None = None


def _fit_functions() -> tuple:
    """The skew fit's two steps. Where numba is loaded already (the monitor's process: the pipeline's
    kernels) its compiled form (:mod:`.clock_kernels`), imported and called once on the first aligner
    made: numba loads a kernel from its cache on its first call, tens of milliseconds (more on a loaded
    host) that a reader would otherwise stall for mid-stream, at the first skew fit (a test of the 7 kHz
    RDT stream lost its tail so). Elsewhere (a reader's own process) the same steps in numpy, without
    numba's import and cache loads at its start (a restarted reader streams again sooner). Both give
    the numbers of the sorted form they replace, to the bit (tests/foundation/test_bus_clock.py)."""
    global _KERNELS
    if "numba" not in sys.modules:
        return _hull_slope_numpy, _lowest_intercept_numpy
    if _KERNELS is None:
        from .clock_kernels import hull_slope, lowest_intercept  # lazy: numba only where it is loaded already

        x = np.arange(4, dtype=np.int64)
        hull_slope(x, x, 3, 2, 1.5, 1e-3)
        lowest_intercept(x, x, 0.5)
        _KERNELS = (hull_slope, lowest_intercept)
    return _KERNELS


def _hull_slope_numpy(x: np.ndarray, y: np.ndarray, span: int, buckets: int, x_mean: float,
                      max_skew: float) -> float:
    """:func:`.clock_kernels.hull_slope` in numpy: x never decreases, so each bucket is a run of samples."""
    bucket = (x - x[0]) * buckets // (span + 1)
    starts = np.flatnonzero(np.concatenate(([True], bucket[1:] != bucket[:-1])))
    lows = np.minimum.reduceat(y, starts)
    run = np.repeat(np.arange(starts.shape[0]), np.diff(np.append(starts, y.shape[0])))
    hits = np.flatnonzero(y == lows[run])  # every sample at its bucket's minimum; the first of each is kept
    first = hits[np.concatenate(([True], run[hits][1:] != run[hits][:-1]))]
    return lower_hull_slope(x[first].astype(np.float64), y[first].astype(np.float64), x_mean, max_skew)


def lower_hull_slope(px: np.ndarray, py: np.ndarray, x_mean: float, max_skew: float) -> float:
    """Slope of the lower convex hull of points (px increasing) on its edge spanning ``x_mean``, clipped
    to +-max_skew; 0.0 for one point."""
    hull: list[tuple[float, float]] = []  # monotone chain
    for p in zip(px.tolist(), py.tolist(), strict=True):
        while len(hull) >= 2:
            (x1, y1), (x2, y2) = hull[-2], hull[-1]
            if (x2 - x1) * (p[1] - y1) - (y2 - y1) * (p[0] - x1) > 0:
                break
            hull.pop()
        hull.append(p)
    if len(hull) < 2:
        return 0.0
    i = next((k for k in range(1, len(hull)) if hull[k][0] >= x_mean), len(hull) - 1)
    (x1, y1), (x2, y2) = hull[i - 1], hull[i]
    return max(-max_skew, min(max_skew, (y2 - y1) / (x2 - x1)))


def _lowest_intercept_numpy(x: np.ndarray, y: np.ndarray, b: float) -> float:
    return float(np.min(y - b * x))


class ClockNotReadyError(RuntimeError):
    """``to_host``/``offset_ns`` before any sample was seen."""


class ClockAligner:
    """Estimates host time of device timestamps for one source. Not thread-safe on its own.

    ``window_s``: device-time span of the sliding window (capped at ``max_samples`` samples).
    ``min_samples``: samples needed before ``ready``. ``estimate_skew``: fit the rate error too.
    ``refit_every``: samples between two skew fits. ``max_skew``: bound on ``|skew|`` (crystal
    oscillators are within ~1e-4). ``min_skew_span_s``: shortest window span for a skew fit.
    """

    def __init__(
        self,
        window_s: float = 2.0,
        *,
        max_samples: int = 4096,
        min_samples: int = 16,
        estimate_skew: bool = True,
        refit_every: int = 32,
        buckets: int = 16,
        max_skew: float = 1e-3,
        min_skew_span_s: float = 0.2,
        jump_ns: int = 500_000_000,
    ) -> None:
        if window_s <= 0 or max_samples < 2 or min_samples < 1 or buckets < 2 or refit_every < 1:
            raise ValueError("invalid ClockAligner parameters")
        self.window_ns = int(window_s * 1e9)
        self.max_samples = max_samples
        self.min_samples = min_samples
        self.estimate_skew = estimate_skew
        self.refit_every = refit_every
        self.buckets = buckets
        self.max_skew = max_skew
        self.min_skew_span_ns = int(min_skew_span_s * 1e9)
        self.jump_ns = jump_ns
        self.resets = 0
        self.capped = 0
        self._hull_slope, self._lowest_intercept = _fit_functions()
        self._reset()

    def _reset(self) -> None:
        self._t0: int | None = None  # reference device time
        self._d0 = 0  # reference offset (t_host - t_device of the first sample)
        self._xs: deque[int] = deque()  # device time - t0
        # the window's (x, y = (t_host - t_device) - d0) for the fit: a ring written twice (at i and
        # i + cap), so that the newest n samples are always one contiguous slice
        cap = self.max_samples + 1
        self._ring_x = np.zeros(2 * cap, dtype=np.int64)
        self._ring_y = np.zeros(2 * cap, dtype=np.int64)
        self._cap = cap
        self._pos = -1  # ring index of the newest sample
        self._mins: deque[tuple[int, int]] = deque()  # monotone deque of (x, y): sliding minimum
        self._last_x = 0
        self._a = 0.0  # offset line y = a + b x, relative to (t0, d0)
        self._b = 0.0
        self._since_fit = 0
        self._fitted = False
        self._capped_at: tuple[int, float] | None = None  # (x, line value there) of the last estimate

    # -- feeding --------------------------------------------------------------------------------
    def update(self, t_device_ns: int, t_host_ns: int) -> None:
        """Add one (device time, host receive time) pair, both in ns."""
        if self._t0 is not None:
            x = t_device_ns - self._t0
            y = (t_host_ns - t_device_ns) - self._d0
            if x < self._last_x or y - (self._a + self._b * x) < -self.jump_ns:
                self.resets += 1
                self._reset()
        if self._t0 is None:
            self._t0, self._d0 = t_device_ns, t_host_ns - t_device_ns
        x = t_device_ns - self._t0
        y = (t_host_ns - t_device_ns) - self._d0
        self._last_x = x
        xs, mins = self._xs, self._mins
        xs.append(x)
        pos = self._pos = (self._pos + 1) % self._cap
        self._ring_x[pos] = self._ring_x[pos + self._cap] = x
        self._ring_y[pos] = self._ring_y[pos + self._cap] = y
        while mins and mins[-1][1] >= y:
            mins.pop()
        mins.append((x, y))
        lo = x - self.window_ns
        while xs[0] < lo or len(xs) > self.max_samples:
            xs.popleft()
        while mins[0][0] < xs[0]:
            mins.popleft()
        if not self.estimate_skew:
            self._a = float(mins[0][1])
        else:
            self._since_fit += 1
            if not self._fitted or self._since_fit >= self.refit_every:
                self._fit()
            elif not self._b:
                self._a = float(mins[0][1])
            else:
                self._a = min(self._a, y - self._b * x)  # keep the line under the new sample
        self._limit_rise(x)

    def _limit_rise(self, x: int) -> None:
        """Hold the line at x to at most the last estimate plus max_skew times the time since."""
        line = self._a + self._b * x
        if self._capped_at is not None:
            cx, cy = self._capped_at
            limit = cy + self.max_skew * (x - cx)
            if line > limit + 1.0:  # 1 ns: rounding
                self._a = limit - self._b * x
                line = limit
                self.capped += 1
        self._capped_at = (x, line)

    def _window(self) -> tuple[np.ndarray, np.ndarray]:
        """The window's x and y, oldest first (views of the ring)."""
        end = self._pos + 1 + self._cap
        start = end - len(self._xs)
        return self._ring_x[start:end], self._ring_y[start:end]

    def _fit(self) -> None:
        self._since_fit = 0
        self._fitted = True
        x, y = self._window()
        span = int(x[-1] - x[0])
        b = 0.0
        if span >= self.min_skew_span_ns and x.shape[0] >= 2 * self.buckets:
            # the slope comes from the lower convex hull of per-bucket minima, on the edge spanning the
            # mean time: it minimises the mean distance of the samples above the line
            b = self._hull_slope(x, y, span, self.buckets, float(x.mean()), self.max_skew)
        self._b = b
        self._a = self._lowest_intercept(x, y, b) if b else float(self._mins[0][1])

    # -- estimates --------------------------------------------------------------------------------
    @property
    def ready(self) -> bool:
        """Enough samples in the window for the estimate to be trusted."""
        return len(self._xs) >= self.min_samples

    @property
    def samples(self) -> int:
        """Samples in the window."""
        return len(self._xs)

    @property
    def skew(self) -> float:
        """Estimated rate error d(t_host - t_device)/d(t_device), dimensionless (x 1e6 for ppm)."""
        return self._b

    @property
    def offset_ns(self) -> int:
        """``t_host - t_device`` for a minimum-delay packet at the newest device time."""
        if self._t0 is None:
            raise ClockNotReadyError("no sample yet")
        return self._d0 + round(self._a + self._b * self._last_x)

    def to_host(self, t_device_ns: int) -> int:
        """Host monotonic time (ns) of device time ``t_device_ns`` (plus the delay floor)."""
        if self._t0 is None:
            raise ClockNotReadyError("no sample yet")
        return t_device_ns + self._d0 + round(self._a + self._b * (t_device_ns - self._t0))
