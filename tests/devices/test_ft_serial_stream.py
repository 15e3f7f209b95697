"""The 1 kHz serial stream: adapter (pyserial) against its emulator in another process, over a pty."""
from __future__ import annotations

import time
from collections import Counter

import numpy as np
import pytest
import serial

from ftc_hw.bus import EVENTS_DEVICE, Bus, WrenchFlag
from ftc_hw.codecs import FTC_1K, StreamParser
from ftc_hw.devices.registry import make_adapter
from ftc_hw.devices.serial_stream import SerialStreamFTAdapter

pytestmark = [pytest.mark.realtime, pytest.mark.timeout(60)]


def _run(ft_sim, frames: int, *, saturated=None, **options):
    return ft_sim.run_until_done("leng2016", "ft-serial-stream", 1000.0, 3, frames, saturated=saturated, **options)


def _check_values(frames, stats, wrench_of) -> None:
    for f in frames:
        k = f.seq - stats["seq_offset"]
        assert np.allclose(f.wrench, wrench_of(k), atol=1e-9), (f.seq, f.wrench)
        assert f.t_device_ns == k * 1_000_000 + stats["t_offset_ns"]


def _faults_after(stats: dict, first: int) -> tuple[Counter, Counter]:
    """Per fault, how many hit samples the adapter surely saw (after ``first``, the first delivered) and how
    many it may have seen (on ``first`` itself and on the destroyed samples just before it)."""
    damaged = set(stats["damaged"])
    edge = first
    while edge - 1 in damaged:
        edge -= 1
    surely, maybe = Counter(), Counter()
    for fault, samples in stats["fault_at"].items():
        for n in samples:
            if n > first:
                surely[fault] += 1
            elif n >= edge:
                maybe[fault] += 1
    return surely, maybe


def test_clean_stream_delivers_every_sample_with_device_time(ft_sim, wrench_of):
    adapter, frames, stats, _ = _run(ft_sim, 1500)
    assert stats["samples"] == 1500 and stats["faults"] == {}
    seqs = [f.seq for f in frames]
    # in order, to the last sample sent (the first ones may precede the adapter's input flush), and
    # nothing lost but what the emulator could not deliver (none, unless the machine stalled the client)
    missing = set(range(seqs[0], stats["last_seq"] + 1)) - set(seqs)
    assert seqs == sorted(seqs) and missing == set(stats["damaged"]), (dict(adapter.counters), stats)
    assert set(stats["faults"]) <= {"overflow", "skipped"}
    _check_values(frames, stats, wrench_of)
    c = adapter.counters
    assert c["seq_gaps"] == c["checksum_errors"] == c["resyncs"] == c["duplicates"] == 0
    assert all(f.flags & WrenchFlag.CLOCK_SUSPECT for f in frames[:adapter.clock.min_samples - 1])
    assert not any(f.flags & WrenchFlag.CLOCK_SUSPECT for f in frames[adapter.clock.min_samples:])
    # device time runs with host time: the aligned host time of a sample precedes its receipt
    last = frames[-1]
    assert 0 <= last.t_host_ns - adapter.clock.to_host(last.t_device_ns) < 50_000_000


def test_every_fault_counted_nothing_corrupted_nothing_else_lost(ft_sim, wrench_of):
    faults = {"drop": 0.01, "corrupt": 0.01, "truncate": 0.01, "duplicate": 0.01, "garbage": 0.01, "delay": 0.005,
              "delay_ms": 5}
    adapter, frames, stats, _ = _run(ft_sim, 3000, faults=faults, seed=7)
    injected = stats["faults"]
    assert all(injected.get(k, 0) > 5 for k in ("drop", "corrupt", "truncate", "duplicate", "garbage"))
    _check_values(frames, stats, wrench_of)  # no corrupted frame reached the bus
    c = adapter.counters
    seqs = [f.seq for f in frames]
    # faults on samples sent before the adapter opened the port (its input flush) were never seen; the
    # destroyed samples just before the first delivered one, and that one's own fault, may or may not be
    seen_surely, seen_maybe = _faults_after(stats, seqs[0])
    for counter, faults_of in (("checksum_errors", ("corrupt", "truncate")), ("resyncs", ("garbage",)),
                               ("duplicates", ("duplicate",))):
        low = sum(seen_surely[f] for f in faults_of)
        assert low <= c[counter] <= low + sum(seen_maybe[f] for f in faults_of), (counter, c, stats["fault_at"])
    assert sum(seen_surely.values()) > 30
    missing = set(range(seqs[0], seqs[-1] + 1)) - set(seqs)
    assert missing == {n for n in stats["damaged"] if seqs[0] <= n <= seqs[-1]}  # lost = what the faults destroyed
    assert c["lost"] == len(missing)
    # each gap flagged exactly on the first frame after it
    flagged = {f.seq for f in frames if f.flags & WrenchFlag.SEQ_GAP}
    assert flagged == {n + 1 for n in missing if n + 1 not in missing}
    assert sum(n for _, n in adapter.gaps) == len(missing)


def test_counters_wrap_and_saturation_bits(ft_sim, wrench_of):
    def sat(k: int) -> np.ndarray:
        return np.array([k % 100 == 0, False, False, False, False, k % 100 == 50])

    # the 16-bit sequence and the 32-bit microsecond clock both wrap during the run
    adapter, frames, stats, _ = _run(ft_sim, 1200, saturated=sat, seq_start=65_536 - 600,
                                     t_device_start_s=(2**32 - 500_000) / 1e6)
    seqs = [f.seq for f in frames]
    assert set(range(seqs[0], seqs[-1] + 1)) - set(seqs) == set(stats["damaged"]), (dict(adapter.counters), stats)
    assert seqs[0] < 65_536 < seqs[-1]
    t_dev = np.array([f.t_device_ns for f in frames])
    assert np.all(np.diff(t_dev) == 1_000_000 * np.diff(seqs)) and t_dev[-1] > 2**32 * 1000
    assert adapter.counters["seq_resets"] == 0 and adapter.clock.resets == 0
    _check_values(frames, stats, wrench_of)
    for f in frames:
        k = f.seq - stats["seq_offset"]
        assert bool(f.flags & WrenchFlag.SATURATED) == (k % 50 == 0)


def test_stall_reports_stale_then_recovered(ft_sim):
    adapter, frames, stats, events = _run(ft_sim, 1500, faults={"stall_s": [[0.6, 0.3]]})
    kinds = [e.kind for e in events if e.source == "ft"]
    assert "stale" in kinds and "recovered" in kinds[kinds.index("stale"):]
    assert adapter.counters["lost"] == stats["faults"]["stalled"] >= 250
    gap = max(b.t_host_ns - a.t_host_ns for a, b in zip(frames, frames[1:], strict=False))
    assert 0.25e9 < gap < 0.5e9


def test_unplug_and_replug_of_the_pty(ft_sim, wrench_of):
    adapter, frames, stats, events = _run(ft_sim, 2500, faults={"disconnect_at_s": 0.8, "reconnect_after_s": 0.3})
    kinds = [e.kind for e in events if e.source == "ft"]
    assert kinds.count("connect") == 2 and "disconnect" in kinds
    _check_values(frames, stats, wrench_of)
    seqs = [f.seq for f in frames]
    unplugged = set(stats["damaged"])
    assert len(unplugged) == stats["faults"]["unplugged"] >= 250
    # besides the unplugged time, only what the device sent before the host had reopened the port, and
    # what was still in the pty's buffer, unread, when it was unplugged (a reader a few ms behind on a
    # loaded host: a real unplug loses that too)
    lost = sorted(set(range(seqs[0], seqs[-1] + 1)) - set(seqs) - unplugged)
    before = [s for s in lost if s < min(unplugged)]
    late = [s for s in lost if s > max(unplugged)]
    assert before == list(range(min(unplugged) - len(before), min(unplugged))) and len(before) < 50, before
    assert late == list(range(max(unplugged) + 1, max(unplugged) + 1 + len(late))) and len(late) < 400


def test_plain_pyserial_reader_decodes_the_stream(ft_sim, wait_for, wrench_of):
    scene, spec = ft_sim.device("leng2016", "ft-serial-stream")
    world = ft_sim.world(1000.0)
    emu = ft_sim.start_emulator(spec, scene, world)
    with serial.Serial(emu.endpoint["endpoint"], 1_000_000, timeout=0.05) as s:
        s.reset_input_buffer()
        parser = StreamParser(FTC_1K)
        got = []
        assert wait_for(lambda: bool(got.extend(parser.feed(s.read(512))) or len(got) > 200), 5.0)
    ft_sim.stop()
    for sample in got:
        assert np.allclose(sample.wrench, wrench_of(sample.seq), atol=1e-9)


def test_lifecycle_idempotent_and_never_silent(tmp_path, ft_sim, wait_for):
    bus = Bus()
    events = bus.subscribe(EVENTS_DEVICE, maxsize=None)
    a = SerialStreamFTAdapter("ft", bus, str(tmp_path / "missing.tty"))
    a.close()  # before open: nothing to do
    with a:
        a.open()  # already open: same reader thread
        assert wait_for(lambda: a.counters["connect_failures"] >= 2 and a.stale, 2.0)
        assert not a.connected.is_set()
    a.close()
    msgs = events.drain()
    assert {"reconnecting", "stale"} <= {e.kind for e in msgs}
    # an unexpected exception in the reader becomes an event, and the reader goes on
    scene, spec = ft_sim.device("leng2016", "ft-serial-stream")
    world = ft_sim.world(1000.0)
    emu = ft_sim.start_emulator(spec, scene, world)
    adapter = make_adapter(spec, bus, emu.endpoint)
    original = adapter._read_once
    calls = {"n": 0}

    def flaky() -> None:
        calls["n"] += 1
        if calls["n"] == 50:
            raise RuntimeError("boom")
        original()

    adapter._read_once = flaky  # type: ignore[method-assign]
    with adapter:
        assert wait_for(lambda: adapter.counters["event_connect"] >= 2, 3.0)
        time.sleep(0.1)
    assert adapter.counters["errors"] == 1
    assert any(e.kind == "error" and "boom" in e.message for e in events.drain())
