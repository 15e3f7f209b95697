"""CAN F/T (ATI Net F/T frames from the DBC): python-can's serial interface against the emulator over a
pty, and the virtual interface in-process."""
from __future__ import annotations

import dataclasses

import can
import numpy as np
import pytest

from ftc_hw.bus import Bus, WrenchFlag
from ftc_hw.codecs.netft_can import OP_BIAS, OP_READ, OP_START, NetFTCodec
from ftc_hw.devices.can_ft import CanFTAdapter
from ftc_hw.devices.registry import make_adapter

pytestmark = [pytest.mark.realtime, pytest.mark.timeout(60)]


def _run(ft_sim, frames: int, *, saturated=None, **options):
    return ft_sim.run_until_done("ur5e", "ft-can", 1000.0, 6, frames, saturated=saturated, **options)


def _check(frames, wrench_of, offset: int = 0) -> None:
    for f in frames:
        assert np.allclose(f.wrench, wrench_of(f.seq - offset), atol=1e-9), f.seq
        assert f.t_device_ns == f.seq * 1_000_000


def test_stream_every_sample_in_order(ft_sim, wrench_of):
    def sat(k: int) -> np.ndarray:
        return np.array([False, False, k % 10 == 0, False, False, False])

    adapter, frames, stats, _ = _run(ft_sim, 1200, saturated=sat)
    # streaming starts on the adapter's request; the first sample only establishes the counter
    undelivered = len(stats["damaged"])  # none, unless the machine stalled the client for 0.3 s
    assert len(frames) == stats["samples"] - 1 - undelivered and adapter.counters["unverified"] == 1
    seqs = [f.seq for f in frames]
    assert set(range(seqs[0], seqs[-1] + 1)) - set(seqs) == set(stats["damaged"])
    _check(frames, wrench_of)
    assert all(bool(f.flags & WrenchFlag.SATURATED) == (f.seq % 10 == 0) for f in frames)
    c = adapter.counters
    assert c["incomplete"] == c["seq_gaps"] == c["checksum_errors"] == c["framing_errors"] == 0


def test_every_fault_counted_nothing_corrupted_nothing_else_lost(ft_sim, wrench_of):
    faults = {"drop": 0.004, "corrupt": 0.004, "truncate": 0.004, "duplicate": 0.004, "garbage": 0.004,
              "delay": 0.002, "delay_ms": 3}
    adapter, frames, stats, _ = _run(ft_sim, 2500, faults=faults, seed=3)
    injected = stats["faults"]
    assert all(injected.get(k, 0) > 10 for k in ("drop", "corrupt", "truncate", "duplicate", "garbage"))
    _check(frames, wrench_of)
    c = adapter.counters
    assert c["checksum_errors"] == injected["corrupt"]  # error frames
    assert c["format_errors"] == injected["truncate"]  # short DLC
    assert c["foreign"] == injected["garbage"]
    assert c["duplicates"] == injected["duplicate"]
    seqs = [f.seq for f in frames]
    missing = set(range(seqs[0], seqs[-1] + 1)) - set(seqs)
    damaged = set(stats["damaged"])
    assert damaged <= missing and c["lost"] == len(missing)
    # beyond what the faults destroyed, only the sample after a malformed status frame (its data
    # cannot be attributed without the counter) is dropped
    extra = missing - damaged
    assert extra <= {n + 1 for n in damaged} and len(extra) <= injected["truncate"]
    flagged = {f.seq for f in frames if f.flags & WrenchFlag.SEQ_GAP}
    assert flagged == {n + 1 for n in missing if n + 1 not in missing}


def test_poll_mode_requests_samples(ft_sim, wait_for, wrench_of):
    scene, spec = ft_sim.device("ur5e", "ft-can", mode="poll", poll_hz=200.0)
    world = ft_sim.world(1000.0, n_joints=6)
    emu = ft_sim.start_emulator(spec, scene, world)
    bus = Bus()
    with make_adapter(spec, bus, emu.endpoint) as adapter:
        assert adapter.wait_connected(5.0)
        assert wait_for(lambda: len(bus.history(adapter.topic)) >= 100, 5.0)
    ft_sim.stop()
    frames = bus.history(adapter.topic)
    _check(frames, wrench_of)
    assert 2.0 <= np.median(np.diff([f.seq for f in frames])) <= 15.0  # 1 kHz samples read at ~200 Hz


def test_virtual_interface_in_process(wait_for, wrench_of):
    """The adapter against a sensor played by the test on python-can's virtual bus."""
    codec = NetFTCodec(base_id=0x30)
    sensor = can.Bus(interface="virtual", channel="ftc-test-can")
    bus = Bus()
    try:
        adapter = CanFTAdapter("ft", bus, "ftc-test-can", interface="virtual", base_id=0x30, silence_s=None)
        with adapter:
            request = sensor.recv(timeout=2.0)
            assert request is not None
            assert (request.arbitration_id, bytes(request.data)) == codec.encode_request(OP_START)
            for k in range(5):
                frames = codec.encode_sample(wrench_of(k), counter=k)
                if k == 2:
                    frames = frames[:1] + frames[2:]  # Fy/Ty lost: the whole sample is dropped
                for arb, data in frames:
                    sensor.send(can.Message(arbitration_id=arb, data=data, is_extended_id=False))
            sensor.send(can.Message(arbitration_id=0x7FF, data=b"\x00", is_error_frame=True))
            assert wait_for(lambda: adapter.counters["checksum_errors"] == 1, 2.0)
    finally:
        sensor.shutdown()
    frames = bus.history("wrench/ft")
    assert [f.seq for f in frames] == [1, 3, 4]  # 0 only establishes the counter
    assert frames[1].flags & WrenchFlag.SEQ_GAP and adapter.counters["incomplete"] == 1
    _check(frames, wrench_of)


def test_the_init_bias_request_biases_what_follows_and_other_opcodes_are_counted(ft_sim, wait_for):
    """Opcode 4 (init/bias, what a public driver sends when it starts: issue 36): the samples that follow
    are less the reading of that moment; an unknown opcode is ignored and counted, never a crash."""
    held = np.array([5.0, -2.5, 30.0, 0.25, -0.5, 0.125])
    scene, spec = ft_sim.device("ur5e", "ft-can")
    world = ft_sim.world(1000.0, n_joints=6, fn=lambda k: held)
    emu = ft_sim.start_emulator(spec, scene, world)
    codec = NetFTCodec(spec.params.get("dbc", "ati_netft_can.dbc"), int(spec.params.get("base_id", 8)))
    with can.Bus(interface="serial", channel=emu.endpoint["channel"], bitrate=1_000_000) as sensor:

        def one_sample(opcode: int = OP_READ) -> np.ndarray:
            arb_id, data = codec.encode_request(opcode)
            sensor.send(can.Message(arbitration_id=arb_id, data=data, is_extended_id=False))
            parts = {}
            while len(parts) < 4:
                msg = sensor.recv(timeout=2.0)
                assert msg is not None
                part = codec.decode(msg.arbitration_id, bytes(msg.data))
                if part is not None and part.role == "data":
                    parts[part.index] = part.value
                elif part is not None and part.role == "status":
                    parts[3] = part.value
            return np.array([parts[i][0] for i in range(3)] + [parts[i][1] for i in range(3)])

        assert np.allclose(one_sample(), held, atol=1e-9)
        for opcode in (0x09, 0xFF):
            arb_id, data = codec.encode_request(opcode)
            sensor.send(can.Message(arbitration_id=arb_id, data=data, is_extended_id=False))
        arb_id, data = codec.encode_request(OP_BIAS)
        sensor.send(can.Message(arbitration_id=arb_id, data=data, is_extended_id=False))
        assert wait_for(lambda: ft_sim.read_stats(emu).get("biases") == 1, 5.0)
        assert np.allclose(one_sample(), 0.0, atol=1e-9)
    assert wait_for(lambda: ft_sim.read_stats(emu).get("requests") == 3, 5.0)  # the stats file lags 0.1 s
    assert ft_sim.read_stats(emu)["bad_requests"] == 2


def test_a_read_request_before_the_emulators_first_tick_is_answered(ft_sim):
    """A request that comes before the emulator's pacing loop has taken its first sample from the world (a client
    that asks at once on a loaded host; here the loop's first tick is 2 s away) gets the world's newest sample,
    not silence."""
    held = np.array([1.0, 2.0, 3.0, 0.1, 0.2, 0.3])
    scene, spec = ft_sim.device("ur5e", "ft-can")
    slow = dataclasses.replace(scene, sensor=dataclasses.replace(scene.sensor, rate_hz=0.5))
    world = ft_sim.world(1000.0, n_joints=6, fn=lambda k: held)
    emu = ft_sim.start_emulator(spec, slow, world)
    codec = NetFTCodec(spec.params.get("dbc", "ati_netft_can.dbc"), int(spec.params.get("base_id", 8)))
    with can.Bus(interface="serial", channel=emu.endpoint["channel"], bitrate=1_000_000) as sensor:
        arb_id, data = codec.encode_request(OP_READ)
        sensor.send(can.Message(arbitration_id=arb_id, data=data, is_extended_id=False))
        msg = sensor.recv(timeout=1.0)
    assert msg is not None and codec.decode(msg.arbitration_id, bytes(msg.data)) is not None
