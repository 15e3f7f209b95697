"""``ftc monitor --ros``: the node ``ftc_monitor`` (the process's one node, :mod:`.context`) publishing the
bus's frames as ROS 2 messages (:class:`~.view.RosView`), from a thread of its own.

The monitor never waits for ROS: the node's thread drains a queue subscription of the bus every ``poll_s``
(a full queue drops its oldest frames, counted in ``dropped``), encodes, and hands the CDR bytes to rclpy's
publishers (``Publisher.publish`` takes serialized messages). A message rclpy refuses is counted per topic
in ``failed``; the monitor's summary and the diagnostics say both. The node follows the user's ROS
environment (``ROS_DOMAIN_ID``, ``ROS_AUTOMATIC_DISCOVERY_RANGE``), as every ROS node does.
"""
from __future__ import annotations

import importlib
import threading
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from ftc_hw.bus import Bus
from ftc_hw.scene import Scene

from . import context
from . import layout as L
from .view import RosMessage, RosView

NODE_NAME = "ftc_monitor"
ACK_WAIT_S = 2.0  # at the stop: how long the subscribers get to acknowledge what was published


def qos(topic: L.Topic) -> QoSProfile:
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=topic.depth, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if topic.latched else DurabilityPolicy.VOLATILE)


def message_class(msgtype: str) -> type:
    """rclpy's class of ``pkg/msg/Name`` (from the extra's message wheels)."""
    pkg, _, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


class RosPublisher:
    """``start()`` / ``stop()``; ``counts`` (published per topic), ``failed`` (per topic), ``dropped`` (frames the
    bus queue dropped), ``skipped`` (frames the view could not use, per reason). ``counters``: the monitor's,
    for the diagnostics."""

    def __init__(self, bus: Bus, scene: Scene, *, namespace: str = L.DEFAULT_NAMESPACE,
                 counters: Callable[[], dict[str, Any]] | None = None, poll_s: float = 0.005,
                 diagnostics_s: float = 1.0, maxsize: int = 200_000) -> None:
        self.bus, self.namespace, self.counters = bus, namespace, counters
        self.view = RosView(scene, namespace=namespace)
        self.poll_s, self.diagnostics_s, self.maxsize = poll_s, diagnostics_s, maxsize
        self.counts: Counter[str] = Counter()
        self.failed: Counter[str] = Counter()
        self.error = ""  # the first failure's message
        self.dropped = 0
        self.unacked: list[str] = []  # topics a subscriber had not acknowledged everything of at the stop
        self._node: Any = None
        self._pubs: dict[str, Any] = {}
        self._sub: Any = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._next_diag = 0

    def start(self) -> RosPublisher:
        self._node = context.acquire(NODE_NAME, unique=False)  # the process's one node (its ROS devices' too)
        for topic in L.TOPICS:
            if topic.live:
                name = topic.full_name(self.namespace)
                self._pubs[name] = self._node.create_publisher(message_class(topic.msgtype), name, qos(topic))
        self._sub = self.bus.subscribe("", maxsize=self.maxsize, prefix=True)
        self._thread = threading.Thread(target=self._run, name="ros-publisher", daemon=True)
        self._thread.start()
        return self

    @property
    def node_name(self) -> str:
        return self._node.get_name()

    def subscribers(self, topic: L.Topic) -> int:
        """How many subscriptions match ``topic`` now (discovery takes up to ~2 s)."""
        return self._pubs[topic.full_name(self.namespace)].get_subscription_count()

    def _publish(self, messages: list[RosMessage]) -> None:
        for m in messages:
            name = m.topic.full_name(self.namespace)
            try:
                self._pubs[name].publish(m.data)
                self.counts[name] += 1
            except Exception as exc:  # noqa: BLE001 - counted, said in the summary and the diagnostics
                self.failed[name] += 1
                self.error = self.error or f"{name}: {type(exc).__name__}: {exc}"

    def _pass(self) -> None:
        for frame in self._sub.drain():
            try:
                self._publish(self.view.feed(frame))
            except Exception as exc:  # noqa: BLE001 - a frame the view cannot translate: counted, never fatal
                self.failed["view"] += 1
                self.error = self.error or f"view: {type(exc).__name__}: {exc}"
        now = time.monotonic_ns()
        if now >= self._next_diag:
            self._next_diag = now + int(self.diagnostics_s * 1e9)
            self._diagnostics(now)

    def _diagnostics(self, now: int) -> None:
        try:  # the monitor's thread counts on while we copy: a copy that fails is taken next time
            counters = dict(self.counters()) if self.counters is not None else {}
        except RuntimeError:
            counters = {}
        published = {**{f"published:{k}": v for k, v in self.counts.items()},
                     **{f"failed:{k}": v for k, v in self.failed.items()}, "dropped": self._sub.drops}
        self._publish([self.view.diagnostics(now, counters, published)])

    def _run(self) -> None:
        while not self._sub.closed:
            self._pass()
            self._stop.wait(self.poll_s)

    def stop(self) -> None:
        """Publish what is queued and a last diagnostics message; the node gone."""
        if self._sub is None:
            return
        self._sub.close()
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=30.0)
        self._next_diag = 0
        self._pass()
        self.dropped = self._sub.drops
        self._sub = None
        deadline = time.monotonic() + ACK_WAIT_S
        for name, pub in self._pubs.items():  # reliable: what was published reaches its subscribers first
            left = max(0.0, deadline - time.monotonic())
            if not pub.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9))):
                self.unacked.append(name)
        for pub in self._pubs.values():
            self._node.destroy_publisher(pub)
        self._pubs.clear()
        context.release()

    def summary(self) -> dict[str, Any]:
        return {"published": dict(self.counts), "failed": dict(self.failed), "dropped": self.dropped,
                "skipped": dict(self.view.skipped), "unacked": list(self.unacked), "error": self.error}
