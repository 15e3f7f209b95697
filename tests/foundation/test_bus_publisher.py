"""RemotePublisher's two paths (ftc_hw.bus.remote): a reader's frame is put on Zenoh by the reader's own
thread when nothing waits; a put that blocks (a congested link: Zenoh's BLOCK) sends the frames after
it through the sender thread, in order, none lost. Zenoh's publisher is replaced by a recorder here:
what is tested is who puts what, in which order (the wire itself: test_bus_remote.py)."""
from __future__ import annotations

import threading
import time

from ftc_hw.bus import Bus
from ftc_hw.bus.remote import RemotePublisher
from ftc_hw.bus.wire import decode_all
from tests.foundation.remote_peer import frame

TOPIC = "wrench/ft"


class _Recorder:
    """Stands for a Zenoh publisher: records the putting thread and the frames' sequence numbers."""

    def __init__(self, block_s: float = 0.0, blocking_puts: int = 0) -> None:
        self.block_s, self.blocking_puts = block_s, blocking_puts
        self.puts: list[tuple[str, list[int]]] = []

    def put(self, payload: bytes) -> None:
        if len(self.puts) < self.blocking_puts:
            time.sleep(self.block_s)
        self.puts.append((threading.current_thread().name, [f.seq for f in decode_all(payload)]))


def _publisher(recorder: _Recorder) -> tuple[Bus, RemotePublisher]:
    bus = Bus(history=100)
    pub = RemotePublisher(None, bus, "cell", prefixes=("wrench/",))  # type: ignore[arg-type]
    pub._publisher = lambda topic: recorder  # type: ignore[method-assign]
    return bus, pub


def test_a_frame_is_put_by_the_publishing_thread_when_nothing_waits():
    rec = _Recorder()
    bus, pub = _publisher(rec)
    for seq in range(20):
        bus.publish(TOPIC, frame(seq, seq))
    pub.close()
    assert [seqs for _, seqs in rec.puts] == [[seq] for seq in range(20)]
    assert {name for name, _ in rec.puts} == {threading.current_thread().name}
    assert pub.sent == 20


def test_a_put_that_blocks_hands_the_next_frames_to_the_sender_thread_in_order():
    rec = _Recorder(block_s=1.5 * RemotePublisher.SLOW_PUT_S, blocking_puts=1)
    bus, pub = _publisher(rec)
    for seq in range(50):
        bus.publish(TOPIC, frame(seq, seq))
    pub.close()
    names = [name for name, _ in rec.puts]
    assert names[0] == threading.current_thread().name  # the first put: the publishing thread's, slow
    assert all(name.startswith("ftc-zenoh-pub-") for name in names[1:]), names  # then the sender's
    assert [seq for _, seqs in rec.puts for seq in seqs] == list(range(50))  # in order, none lost
    assert pub.sent == 50


def test_frames_published_while_a_put_is_under_way_wait_and_keep_their_order():
    rec = _Recorder(block_s=0.001, blocking_puts=10**6)  # every put takes 1 ms, none counted slow
    bus, pub = _publisher(rec)
    threads = [threading.Thread(target=lambda k=k: [bus.publish(TOPIC, frame(k * 100 + i, i)) for i in range(30)])
               for k in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    pub.close()
    seqs = [seq for _, s in rec.puts for seq in s]
    assert sorted(seqs) == sorted(k * 100 + i for k in range(3) for i in range(30))  # none lost, none twice
    for k in range(3):  # each thread's frames in the order it published them
        mine = [s for s in seqs if s // 100 == k]
        assert mine == sorted(mine)
