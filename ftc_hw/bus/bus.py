"""The timestamped bus: topics, per-topic history, subscribers, time queries.

Topic conventions (plain strings, see the ``*_topic`` helpers):

* ``wrench/<source>``  :class:`WrenchFrame` from force/torque sensor ``<source>``
* ``joints/<source>``  :class:`JointFrame` from arm ``<source>``
* ``events/contact``   :class:`ContactEvent`
* ``events/device``    :class:`DeviceEvent` (connect, error, stale, ...; the bus and watchdog post here)

Publishing (any thread) appends the frame to the topic's bounded history ring and hands it to the
topic's subscribers in the publisher's thread:

* callback subscribers are called synchronously; an exception is counted on the subscription and
  reported as ``DeviceEvent(kind="error", source="bus")`` on ``events/device`` (at most one report per
  subscription per ``error_report_interval_s``; an error raised while reporting is only counted);
* queue subscribers get the frame appended to a bounded queue. When the queue is full the **oldest**
  pending frame is dropped (fresh data matters more to a late consumer) and counted in ``drops``:
  a slow consumer never blocks a publisher.

History and time queries assume frames arrive in nondecreasing ``t_host_ns`` per topic (true when
one reader thread stamps ``time.monotonic_ns()`` on receipt). An out-of-order frame is counted
(``stats(topic).out_of_order``) and inserted at its sorted position, so ``window`` and ``sample_at``
always see a sorted history; subscribers receive frames in publish order. With several threads
publishing on one topic, each frame is delivered exactly once but their interleaving is unspecified.
"""

from __future__ import annotations

import enum
import logging
import sys
import threading
import time
from bisect import bisect_left, bisect_right
from collections import deque
from collections.abc import Callable, Mapping
from itertools import islice
from operator import attrgetter
from typing import Any, Literal

from .frames import ContactEvent, DeviceEvent, Frame, JointFrame, WrenchFrame
from .history import SamplingPolicy, bracket
from .sampling import hold as _hold
from .sampling import interpolate as _interpolate
from .stats import StatsSnapshot, StreamStats
from .subscription import Subscription

__all__ = ["EVENTS_CONTACT", "EVENTS_DEVICE", "Bus", "StaleDataError", "frame_topic", "joints_topic", "wrench_topic"]

log = logging.getLogger(__name__)

EVENTS_CONTACT = "events/contact"
EVENTS_DEVICE = "events/device"

_T_HOST = attrgetter("t_host_ns")


class _Default(enum.Enum):
    DEFAULT = 0


_DEFAULT = _Default.DEFAULT
_STATS_BATCH = 1024  # frames fed to a topic's StreamStats at once (amortises the numpy call)


def wrench_topic(source: str) -> str:
    """``"wrench/<source>"``."""
    return f"wrench/{source}"


def joints_topic(source: str) -> str:
    """``"joints/<source>"``."""
    return f"joints/{source}"


def frame_topic(frame: Any) -> str | None:
    """The topic a bus frame is published on (the conventions above), None for another object."""
    if isinstance(frame, WrenchFrame):
        return wrench_topic(frame.source)
    if isinstance(frame, JointFrame):
        return joints_topic(frame.source)
    if isinstance(frame, ContactEvent):
        return EVENTS_CONTACT
    if isinstance(frame, DeviceEvent):
        return EVENTS_DEVICE
    return None


class StaleDataError(LookupError):
    """``sample_at`` refused: no data close enough to the requested time (would extrapolate)."""

    def __init__(self, message: str, *, topic: str, t_ns: int, gap_ns: int | None, limit_ns: int) -> None:
        super().__init__(message)
        self.topic = topic
        self.t_ns = t_ns
        self.gap_ns = gap_ns
        self.limit_ns = limit_ns


class _Topic:
    __slots__ = ("name", "lock", "ring", "last_t", "count", "fed", "batch", "stats", "subs")

    def __init__(self, name: str, history: int, subs: tuple[Callable[[Any], None], ...]) -> None:
        self.name = name
        self.lock = threading.Lock()
        self.ring: deque[Any] = deque(maxlen=history)
        self.last_t = -sys.maxsize  # newest t_host_ns stored
        self.count = 0  # frames published
        self.fed = 0  # frames already fed to stats; the rest are the ring's newest count - fed frames
        self.batch = min(history, _STATS_BATCH)
        self.stats = StreamStats()
        self.subs = subs  # push callables of matching subscriptions, resolved at subscribe time


class Bus:
    """Thread-safe publish/subscribe bus with per-topic history, statistics and time queries.

    ``history``: frames kept per topic (``topic_history`` overrides it for given topics).
    ``max_gap_ns``: default limit of :meth:`sample_at`. ``default_maxsize``: queue length of queue
    subscriptions. ``error_report_interval_s``: minimum time between two error reports of one
    callback subscription (0 reports every failure).
    """

    def __init__(
        self,
        history: int = 20_000,
        *,
        topic_history: Mapping[str, int] | None = None,
        max_gap_ns: int = 20_000_000,
        default_maxsize: int = 8192,
        error_report_interval_s: float = 1.0,
    ) -> None:
        for n in (history, *(topic_history or {}).values()):
            if n < 2:
                raise ValueError(f"history must be >= 2 frames, got {n}")
        self.default_history = history
        self.max_gap_ns = max_gap_ns
        self.default_maxsize = default_maxsize
        self._topic_history = dict(topic_history or {})
        self._report_interval_ns = int(error_report_interval_s * 1e9)
        self._lock = threading.Lock()  # guards topic creation and subscription changes
        self._topics: dict[str, _Topic] = {}
        self._subs: list[Subscription] = []
        self._tls = threading.local()
        self.callback_errors = 0

    # -- publish ------------------------------------------------------------------------------
    def publish(self, topic: str, frame: Frame) -> None:
        """Store ``frame`` in ``topic``'s history and deliver it to the topic's subscribers."""
        ts = self._topics.get(topic)
        if ts is None:
            ts = self._create_topic(topic)
        t = frame.t_host_ns
        with ts.lock:
            if t >= ts.last_t:
                ts.ring.append(frame)
                ts.last_t = t
                ts.count += 1
                if ts.count - ts.fed >= ts.batch:
                    self._feed_stats(ts)
            else:
                self._store_out_of_order(ts, frame)
        for push in ts.subs:
            try:
                push(frame)
            except Exception as exc:
                self._callback_failed(topic, push, exc)

    def _create_topic(self, topic: str) -> _Topic:
        with self._lock:
            ts = self._topics.get(topic)
            if ts is None:
                subs = tuple(s._push for s in self._subs if _matches(s, topic))
                ts = _Topic(topic, self._topic_history.get(topic, self.default_history), subs)
                self._topics[topic] = ts
            return ts

    @staticmethod
    def _feed_stats(ts: _Topic) -> None:
        k = ts.count - ts.fed
        if k <= 0:
            return
        frames = list(islice(reversed(ts.ring), k))
        frames.reverse()
        seq = [f.seq for f in frames] if hasattr(frames[0], "seq") else None
        ts.stats.update_many([f.t_host_ns for f in frames], seq)
        ts.fed = ts.count

    def _store_out_of_order(self, ts: _Topic, frame: Any) -> None:
        self._feed_stats(ts)  # the pending frames must be the ring's tail when fed
        ring = ts.ring
        pos = bisect_right(ring, frame.t_host_ns, key=_T_HOST)
        if len(ring) < ring.maxlen:  # type: ignore[operator]
            ring.insert(pos, frame)
        elif pos > 0:  # full: make room by evicting the oldest, as append would
            ring.popleft()
            ring.insert(pos - 1, frame)
        # else: older than the whole retained history, it would be evicted at once
        ts.count += 1
        ts.fed = ts.count
        ts.stats.update(frame.t_host_ns, getattr(frame, "seq", None))

    def _callback_failed(self, topic: str, push: Callable[[Any], None], exc: Exception) -> None:
        sub: Subscription = push.__self__  # type: ignore[attr-defined]
        with sub._lock:
            sub.errors += 1
            errors = sub.errors
        with self._lock:
            self.callback_errors += 1
        if getattr(self._tls, "reporting", False):
            return  # raised while reporting an error: count only, no recursion
        now = time.monotonic_ns()
        last = sub._last_report_ns
        if last is not None and now - last < self._report_interval_ns:
            return
        sub._last_report_ns = now
        name = getattr(sub.callback, "__qualname__", repr(sub.callback))
        message = f"subscriber callback {name} raised {exc!r} on topic {topic!r}"
        log.error("%s", message, exc_info=exc if errors == 1 else None)
        self._tls.reporting = True
        try:
            self.publish(
                EVENTS_DEVICE,
                DeviceEvent.make(
                    now, "bus", "error", message, {"errors": errors, "total": self.callback_errors}
                ),
            )
        finally:
            self._tls.reporting = False

    # -- subscribe ------------------------------------------------------------------------------
    def subscribe(
        self,
        topic_or_prefix: str,
        callback: Callable[[Any], Any] | None = None,
        *,
        maxsize: int | None | Literal[_Default.DEFAULT] = _DEFAULT,
        prefix: bool | None = None,
        first: bool = False,
    ) -> Subscription:
        """Subscribe to a topic or a prefix of topics.

        ``prefix=None`` treats ``""`` (all topics) and patterns ending in ``"/"`` (e.g. ``"wrench/"``)
        as prefixes, anything else as an exact topic. With ``callback`` the frames are passed to it in
        the publisher's thread, otherwise they are queued (``maxsize`` frames, default
        ``default_maxsize``; None for unbounded, use with care). Subscribers get a frame in the order
        they subscribed; ``first`` puts this one ahead of those before it (a reflex that must not wait
        for a recorder or a forwarder).
        """
        is_prefix = (topic_or_prefix == "" or topic_or_prefix.endswith("/")) if prefix is None else prefix
        if maxsize is _DEFAULT:
            maxsize = self.default_maxsize
        if maxsize is not None and maxsize < 1:
            raise ValueError(f"maxsize must be >= 1 or None, got {maxsize}")
        sub = Subscription(self, topic_or_prefix, is_prefix, callback, maxsize)
        with self._lock:
            if first:
                self._subs.insert(0, sub)
            else:
                self._subs.append(sub)
            for name, ts in self._topics.items():
                if _matches(sub, name):
                    ts.subs = (sub._push, *ts.subs) if first else (*ts.subs, sub._push)
        return sub

    def _unsubscribe(self, sub: Subscription) -> None:
        with self._lock:
            if sub in self._subs:
                self._subs.remove(sub)
            for ts in self._topics.values():
                if any(p is sub._push for p in ts.subs):
                    ts.subs = tuple(p for p in ts.subs if p is not sub._push)

    # -- queries ------------------------------------------------------------------------------
    def topics(self) -> list[str]:
        """Topics that have received at least one frame, sorted."""
        return sorted(self._topics)

    def latest(self, topic: str) -> Any | None:
        """Newest frame (by ``t_host_ns``) of ``topic``, or None."""
        ts = self._topics.get(topic)
        if ts is None:
            return None
        try:
            return ts.ring[-1]
        except IndexError:
            return None

    def history(self, topic: str) -> list[Any]:
        """Copy of the retained history of ``topic``, oldest first."""
        ts = self._topics.get(topic)
        if ts is None:
            return []
        with ts.lock:
            return list(ts.ring)

    def window(self, topic: str, t0_ns: int, t1_ns: int) -> list[Any]:
        """Retained frames with ``t0_ns <= t_host_ns <= t1_ns``, oldest first."""
        ts = self._topics.get(topic)
        if ts is None or t1_ns < t0_ns:
            return []
        with ts.lock:
            ring = ts.ring
            lo = bisect_left(ring, t0_ns, key=_T_HOST)
            hi = bisect_right(ring, t1_ns, key=_T_HOST)
            return list(islice(ring, lo, hi))

    def stats(self, topic: str) -> StatsSnapshot:
        """Statistics of ``topic``; raises KeyError for a topic that never received a frame."""
        ts = self._topics.get(topic)
        if ts is None:
            raise KeyError(topic)
        with ts.lock:
            self._feed_stats(ts)
            return ts.stats.snapshot()

    def sample_at(
        self, topic: str, t_ns: int, max_gap_ns: int | None = None, *, hold: bool = True
    ) -> JointFrame | WrenchFrame:
        """The state of a joint (or wrench) topic at host time ``t_ns``, never extrapolated.

        * between two frames at most ``max_gap_ns`` apart (default ``Bus.max_gap_ns``): linear
          interpolation of every array field (and of ``t_device_ns`` when both have one); the result
          has ``t_host_ns == t_ns``, the earlier frame's ``seq``, both frames' flags and ``INTERPOLATED``;
        * exactly at a frame's time: that frame itself;
        * after the newest frame by at most ``max_gap_ns`` and ``hold=True``: the newest frame's data
          with ``t_host_ns == t_ns``, ``t_device_ns=None`` and the ``HELD`` flag (zero-order hold);
        * otherwise (before the oldest retained frame, wider gap, too far after): :class:`StaleDataError`.
        """
        limit = self.max_gap_ns if max_gap_ns is None else max_gap_ns
        ts = self._topics.get(topic)
        if ts is None:
            raise StaleDataError(
                f"no frame on {topic!r}", topic=topic, t_ns=t_ns, gap_ns=None, limit_ns=limit
            )
        policy = SamplingPolicy(limit, "hold" if hold else "none", limit)
        with ts.lock:
            ring = ts.ring
            where = bracket(ring, t_ns, policy, key=_T_HOST)
            if isinstance(where, str):
                raise _stale(topic, t_ns, where, ring, limit, hold)
            a = ring[where.i]
            b = None if where.j is None else ring[where.j]
        if b is None:
            return a if a.t_host_ns == t_ns else _hold(a, t_ns)
        return _interpolate(a, b, t_ns)


def _stale(topic: str, t_ns: int, why: str, ring: deque, limit: int, hold: bool) -> StaleDataError:
    """Why ``sample_at`` has no state for ``t_ns`` (``history.bracket``'s reason), in words and figures."""
    if not ring:
        return StaleDataError(f"no frame on {topic!r}", topic=topic, t_ns=t_ns, gap_ns=None, limit_ns=limit)
    if why == "before":
        gap = ring[0].t_host_ns - t_ns
        msg = f"{topic}: t_ns is {gap / 1e6:.3f} ms before the oldest retained frame"
    elif why == "late":
        gap = t_ns - ring[-1].t_host_ns
        msg = (f"{topic}: t_ns is {gap / 1e6:.3f} ms after the newest frame (limit {limit / 1e6:.3f} ms"
               f"{'' if hold else ', hold disabled'})")
    else:
        i = bisect_right(ring, t_ns, key=_T_HOST)
        gap = ring[i].t_host_ns - ring[i - 1].t_host_ns
        msg = f"{topic}: bracketing frames are {gap / 1e6:.3f} ms apart (limit {limit / 1e6:.3f} ms)"
    return StaleDataError(msg, topic=topic, t_ns=t_ns, gap_ns=gap, limit_ns=limit)


def _matches(sub: Subscription, topic: str) -> bool:
    return topic.startswith(sub.pattern) if sub.is_prefix else topic == sub.pattern
