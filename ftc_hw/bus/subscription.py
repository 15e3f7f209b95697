"""Subscriptions: what :meth:`Bus.subscribe <ftc_hw.bus.bus.Bus.subscribe>` returns.

A subscription either calls a callback in the publisher's thread or queues frames for one consumer
thread. A full queue drops its **oldest** pending frame (a late consumer wants fresh data) and counts
it in ``drops``; the publisher never waits for a consumer.
"""

from __future__ import annotations

import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from queue import Empty
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .bus import Bus

__all__ = ["Empty", "Subscription", "SubscriptionClosed"]


class SubscriptionClosed(Exception):
    """``get`` on a closed subscription whose queue is empty."""


class Subscription:
    """A callback or queue subscription returned by :meth:`Bus.subscribe`.

    Queue subscriptions are read by one consumer thread with :meth:`get`, :meth:`get_nowait`,
    :meth:`drain` or iteration (blocks until the subscription is closed). Counters:
    ``delivered`` (frames handed to the callback without error / taken out of the queue), ``drops``
    (frames discarded because the queue was full), ``errors`` (callback exceptions).
    """

    __slots__ = (
        "_bus",
        "pattern",
        "is_prefix",
        "callback",
        "maxsize",
        "_q",
        "_event",
        "_waiters",
        "_lock",
        "_closed",
        "_last_report_ns",
        "_push",
        "delivered",
        "drops",
        "errors",
        "__weakref__",
    )

    def __init__(
        self,
        bus: Bus,
        pattern: str,
        is_prefix: bool,
        callback: Callable[[Any], Any] | None,
        maxsize: int | None,
    ) -> None:
        self._bus = bus
        self.pattern = pattern
        self.is_prefix = is_prefix
        self.callback = callback
        self.maxsize = sys.maxsize if maxsize is None else maxsize
        self._q: deque[Any] | None = None if callback is not None else deque()
        self._event = threading.Event()
        self._waiters = 0
        self._lock = threading.Lock()
        self._closed = False
        self._last_report_ns: int | None = None
        self.delivered = 0
        self.drops = 0
        self.errors = 0
        self._push: Callable[[Any], None] = self._push_callback if callback is not None else self._push_queue

    # -- publisher side (hot path) ------------------------------------------------------------
    def _push_callback(self, frame: Any) -> None:
        self.callback(frame)  # type: ignore[misc]
        with self._lock:  # prefix subscriptions are pushed to from several publisher threads
            self.delivered += 1

    def _push_queue(self, frame: Any) -> None:
        q = self._q
        q.append(frame)  # type: ignore[union-attr]
        if len(q) > self.maxsize:  # type: ignore[arg-type]
            self._drop_oldest()
        if self._waiters and not self._event.is_set():
            self._event.set()

    def _drop_oldest(self) -> None:
        try:
            self._q.popleft()  # type: ignore[union-attr]
        except IndexError:  # the consumer emptied the queue meanwhile: nothing dropped
            return
        with self._lock:  # several publisher threads may drop at once
            self.drops += 1

    # -- consumer side ----------------------------------------------------------------------------
    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def pending(self) -> int:
        """Frames waiting in the queue (0 for callback subscriptions)."""
        return 0 if self._q is None else len(self._q)

    def _queue(self) -> deque[Any]:
        if self._q is None:
            raise TypeError("callback subscription: frames go to the callback, there is no queue")
        return self._q

    def get_nowait(self) -> Any:
        """Next frame; raises :class:`queue.Empty` (or :class:`SubscriptionClosed` once closed)."""
        try:
            frame = self._queue().popleft()
        except IndexError:
            if self._closed:
                raise SubscriptionClosed(f"subscription {self.pattern!r} is closed") from None
            raise Empty from None
        self.delivered += 1
        return frame

    def get(self, timeout: float | None = None) -> Any:
        """Next frame, waiting up to ``timeout`` s (forever if None).

        Raises :class:`queue.Empty` on timeout, :class:`SubscriptionClosed` once closed and drained.
        """
        q = self._queue()
        try:
            frame = q.popleft()
        except IndexError:
            frame = self._wait(q, timeout)
        self.delivered += 1
        return frame

    def _wait(self, q: deque[Any], timeout: float | None) -> Any:
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            if self._closed and not q:
                raise SubscriptionClosed(f"subscription {self.pattern!r} is closed")
            remaining = None if deadline is None else deadline - time.monotonic()
            if remaining is not None and remaining <= 0 and not q:
                raise Empty
            with self._lock:
                self._waiters += 1
            try:
                self._event.clear()
                # Re-check after announcing ourselves: a publisher that appended before reading
                # _waiters is seen here, one that appended after will set the event.
                if not q and not self._closed:
                    self._event.wait(remaining)
            finally:
                with self._lock:
                    self._waiters -= 1
            try:
                return q.popleft()
            except IndexError:
                continue

    def drain(self, max_frames: int | None = None) -> list[Any]:
        """All pending frames (at most ``max_frames``), without waiting."""
        q = self._queue()
        out: list[Any] = []
        pop = q.popleft
        n = sys.maxsize if max_frames is None else max_frames
        try:
            while len(out) < n:
                out.append(pop())
        except IndexError:
            pass
        self.delivered += len(out)
        return out

    def __iter__(self) -> Iterator[Any]:
        """Yield frames as they come; ends when the subscription is closed and drained."""
        while True:
            try:
                yield self.get()
            except SubscriptionClosed:
                return

    def close(self) -> None:
        """Stop receiving frames (idempotent). Pending frames stay readable.

        A publish already in flight in another thread may still deliver one frame after this returns.
        """
        if self._closed:
            return
        self._closed = True
        self._bus._unsubscribe(self)
        self._event.set()

    def __enter__(self) -> Subscription:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        kind = "callback" if self.callback is not None else f"queue(maxsize={self.maxsize})"
        return (
            f"Subscription({self.pattern!r}{'*' if self.is_prefix else ''}, {kind}, "
            f"delivered={self.delivered}, drops={self.drops}, errors={self.errors})"
        )
