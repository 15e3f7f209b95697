"""Publish/subscribe: ordering, prefixes, bounded queues and drops, callback errors, threads."""

import threading

import numpy as np
import pytest

from ftc_hw.bus import (
    EVENTS_DEVICE,
    Bus,
    DeviceEvent,
    Empty,
    SubscriptionClosed,
    WrenchFrame,
    joints_topic,
    wrench_topic,
)

_W = np.zeros(6)
_W.flags.writeable = False


def wf(t: int, seq: int | None = None, source: str = "ft0") -> WrenchFrame:
    return WrenchFrame(t, None, t if seq is None else seq, source, _W)


def test_topic_helpers():
    assert wrench_topic("ft0") == "wrench/ft0" and joints_topic("ur") == "joints/ur"


def test_order_preserved_in_history_and_subscribers():
    bus = Bus()
    q = bus.subscribe("wrench/ft0", maxsize=None)
    seen = []
    bus.subscribe("wrench/ft0", seen.append)
    frames = [wf(t) for t in (1, 2, 2, 5, 9)]
    for f in frames:
        bus.publish("wrench/ft0", f)
    assert bus.history("wrench/ft0") == frames
    assert seen == frames
    assert q.drain() == frames
    assert q.delivered == 5 and q.drops == 0
    assert bus.latest("wrench/ft0") is frames[-1]
    assert bus.latest("wrench/none") is None
    assert bus.topics() == ["wrench/ft0"]


def test_history_is_bounded():
    bus = Bus(history=4, topic_history={"wrench/big": 10})
    for t in range(20):
        bus.publish("wrench/ft0", wf(t))
        bus.publish("wrench/big", wf(t))
    assert [f.t_host_ns for f in bus.history("wrench/ft0")] == [16, 17, 18, 19]
    assert len(bus.history("wrench/big")) == 10
    assert bus.stats("wrench/ft0").count == 20


def test_out_of_order_frame_is_counted_and_stored_sorted():
    bus = Bus(history=5)
    got = bus.subscribe("wrench/ft0", maxsize=None)
    for t in (10, 20, 30):
        bus.publish("wrench/ft0", wf(t))
    late = wf(15)
    bus.publish("wrench/ft0", late)
    assert [f.t_host_ns for f in bus.history("wrench/ft0")] == [10, 15, 20, 30]
    assert [f.t_host_ns for f in got.drain()] == [10, 20, 30, 15]  # subscribers: publish order
    assert bus.latest("wrench/ft0").t_host_ns == 30
    bus.publish("wrench/ft0", wf(40))
    bus.publish("wrench/ft0", wf(12))  # full ring: evicts the oldest (10), stays sorted
    assert [f.t_host_ns for f in bus.history("wrench/ft0")] == [12, 15, 20, 30, 40]
    bus.publish("wrench/ft0", wf(1))  # older than the whole full ring: not retained
    assert [f.t_host_ns for f in bus.history("wrench/ft0")] == [12, 15, 20, 30, 40]
    s = bus.stats("wrench/ft0")
    assert s.out_of_order == 3 and s.count == 7 and s.last_t_host_ns == 40


def test_prefix_and_exact_subscriptions():
    bus = Bus()
    everything = bus.subscribe("", maxsize=None)
    wrenches = bus.subscribe("wrench/", maxsize=None)
    exact = bus.subscribe("wrench/ft", maxsize=None)  # no trailing "/": exact topic
    forced = bus.subscribe("wrench/ft", maxsize=None, prefix=True)
    bus.publish("wrench/ft0", a := wf(1))
    bus.publish("wrench/ft", b := wf(2))
    bus.publish("joints/arm", c := wf(3))
    late = bus.subscribe("joints/", maxsize=None)  # subscribing after the topic exists
    bus.publish("joints/arm", d := wf(4))
    assert everything.drain() == [a, b, c, d]
    assert wrenches.drain() == [a, b]
    assert exact.drain() == [b]
    assert forced.drain() == [a, b]
    assert late.drain() == [d]


def test_close_is_idempotent_and_stops_delivery():
    bus = Bus()
    with bus.subscribe("wrench/", maxsize=None) as sub:
        bus.publish("wrench/ft0", a := wf(1))
    assert sub.closed
    sub.close()
    bus.publish("wrench/ft0", wf(2))
    bus.publish("wrench/ft1", wf(3))  # new topic after close
    assert sub.get_nowait() is a  # pending frames stay readable
    with pytest.raises(SubscriptionClosed):
        sub.get_nowait()
    with pytest.raises(SubscriptionClosed):
        sub.get(timeout=0.01)


def test_queue_full_drops_oldest_counts_exactly_and_never_blocks():
    bus = Bus()
    sub = bus.subscribe("wrench/ft0", maxsize=10)
    frames = [wf(t) for t in range(1000)]
    for f in frames:  # nobody consumes: a blocking publisher would hang here
        bus.publish("wrench/ft0", f)
    assert sub.drops == 990 and sub.pending == 10 and sub.delivered == 0
    assert sub.drain() == frames[-10:]
    assert sub.delivered == 10
    for f in frames[:3]:
        bus.publish("wrench/ft0", f)
    assert sub.drops == 990  # room again: no more drops


def test_get_timeout_and_blocking_get():
    bus = Bus()
    sub = bus.subscribe("wrench/ft0")
    with pytest.raises(Empty):
        sub.get(timeout=0.01)
    with pytest.raises(Empty):
        sub.get_nowait()
    f = wf(1)
    threading.Timer(0.05, bus.publish, args=("wrench/ft0", f)).start()
    assert sub.get(timeout=10) is f


def test_iteration_ends_when_closed():
    bus = Bus()
    sub = bus.subscribe("wrench/ft0", maxsize=None)
    out = []
    reader = threading.Thread(target=lambda: out.extend(sub))
    reader.start()
    frames = [wf(t) for t in range(100)]
    for f in frames:
        bus.publish("wrench/ft0", f)
    while sub.pending:
        threading.Event().wait(0.001)
    sub.close()
    reader.join(10)
    assert not reader.is_alive()
    assert out == frames


def test_subscribers_get_a_frame_in_subscription_order_and_first_goes_ahead():
    """The stop reflex subscribes ``first``: an onset reaches it before a recorder or a forwarder that
    subscribed earlier, on a topic that exists already and on one created after."""
    bus = Bus()
    order: list[str] = []
    bus.publish("wrench/ft0", wf(0))  # the topic exists before the subscriptions
    bus.subscribe("wrench/", lambda f: order.append("recorder"))
    bus.subscribe("wrench/ft0", lambda f: order.append("forwarder"))
    bus.subscribe("wrench/", lambda f: order.append("reflex"), first=True)
    bus.subscribe("wrench/ft0", lambda f: order.append("view"))
    bus.publish("wrench/ft0", wf(1))
    assert order == ["reflex", "recorder", "forwarder", "view"]
    order.clear()
    bus.publish("wrench/ft1", wf(2))  # a topic created after them: the same order
    assert order == ["reflex", "recorder"]


def test_callback_subscription_has_no_queue():
    sub = Bus().subscribe("wrench/ft0", lambda f: None)
    with pytest.raises(TypeError):
        sub.get_nowait()


def test_callback_exception_is_contained_counted_and_reported():
    bus = Bus(error_report_interval_s=0)
    events = bus.subscribe(EVENTS_DEVICE, maxsize=None)
    good = []

    def bad(frame):
        if frame.seq % 2:
            raise RuntimeError("odd frame")

    failing = bus.subscribe("wrench/ft0", bad)
    bus.subscribe("wrench/ft0", good.append)  # registered after the failing one
    frames = [wf(t) for t in range(6)]
    for f in frames:
        bus.publish("wrench/ft0", f)  # must not raise
    assert good == frames
    assert failing.errors == 3 and failing.delivered == 3
    assert bus.callback_errors == 3
    reports = events.drain()
    assert len(reports) == 3
    assert all(isinstance(e, DeviceEvent) and e.kind == "error" and e.source == "bus" for e in reports)
    assert "odd frame" in reports[0].message and "wrench/ft0" in reports[0].message
    assert [e.counters["errors"] for e in reports] == [1, 2, 3]


def test_error_reports_are_rate_limited():
    bus = Bus(error_report_interval_s=3600)
    events = bus.subscribe(EVENTS_DEVICE, maxsize=None)
    sub = bus.subscribe("wrench/ft0", lambda f: 1 / 0)
    for t in range(50):
        bus.publish("wrench/ft0", wf(t))
    assert sub.errors == 50
    assert len(events.drain()) == 1


def test_failing_catch_all_callback_does_not_recurse():
    bus = Bus(error_report_interval_s=0)

    def always_fails(frame):
        raise ValueError("nope")

    sub = bus.subscribe("", always_fails)  # also receives its own error reports
    events = bus.subscribe(EVENTS_DEVICE, maxsize=None)
    for t in range(3):
        bus.publish("wrench/ft0", wf(t))
    # per frame: one error on wrench/ft0, one on the error report it triggered (not reported again)
    assert sub.errors == 6
    assert len(events.drain()) == 3


def test_four_publisher_threads_lose_nothing():
    bus = Bus(history=100_000)
    n, n_threads = 8_000, 4  # 64 000 publishes: several of the interpreter's thread switches each
    everything = bus.subscribe("", maxsize=None)
    counted = bus.subscribe("wrench/", lambda f: None)
    shared = bus.subscribe("wrench/shared", maxsize=None)
    start = threading.Barrier(n_threads)

    def worker(k: int) -> None:
        src = f"ft{k}"
        start.wait()
        for i in range(n):
            f = WrenchFrame(i, None, i, src, _W)
            bus.publish(f"wrench/{src}", f)
            bus.publish("wrench/shared", f)

    threads = [threading.Thread(target=worker, args=(k,)) for k in range(n_threads)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    got = everything.drain()
    assert len(got) == 2 * n * n_threads and everything.drops == 0
    assert counted.delivered == 2 * n * n_threads and counted.errors == 0
    shared_got = shared.drain()
    for k in range(n_threads):
        assert [f.seq for f in bus.history(f"wrench/ft{k}")] == list(range(n))
        # each thread's frames reach a subscriber in that thread's publish order
        assert [f.seq for f in shared_got if f.source == f"ft{k}"] == list(range(n))
    shared_hist = bus.history("wrench/shared")
    assert len(shared_hist) == n * n_threads
    assert [f.t_host_ns for f in shared_hist] == sorted(f.t_host_ns for f in shared_hist)
    for k in range(n_threads):
        assert sum(f.source == f"ft{k}" for f in shared_hist) == n


def test_invalid_arguments():
    with pytest.raises(ValueError):
        Bus(history=1)
    with pytest.raises(ValueError):
        Bus().subscribe("wrench/", maxsize=0)
    with pytest.raises(KeyError):
        Bus().stats("wrench/none")
