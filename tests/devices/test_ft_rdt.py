"""ATI Net F/T over Ethernet (RDT over UDP, calibration over HTTP): the adapter and a plain socket client
written from ATI's RDT description against the emulator in its own process, real sockets on loopback."""
from __future__ import annotations

import http.server
import socket
import struct
import threading
import urllib.request
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from ftc_hw.bus import EVENTS_DEVICE, Bus, WrenchFlag
from ftc_hw.devices.registry import make_adapter
from ftc_hw.scene import DeviceSpec

pytestmark = [pytest.mark.realtime, pytest.mark.timeout(60)]
RATE = 7000.0
PERIOD_NS = round(1e9 / RATE)


def _run(ft_sim, frames: int, *, saturated=None, **options):
    options.setdefault("port", 0)
    return ft_sim.run_until_done("ur5e-netft", "ft-rdt", RATE, 6, frames, saturated=saturated, **options)


def _seqs_match_world(frames, wrench_of) -> int:
    """The world sample index of ft_sequence 0 (the box booted at its first sample), modulo the synthetic
    wrenches' period (2001 samples)."""
    first = frames[0]
    offset = next(k for k in range(0, 20000) if np.allclose(first.wrench, wrench_of(k + first.seq), atol=1e-9))
    for f in frames:
        assert np.allclose(f.wrench, wrench_of(f.seq + offset), atol=1e-9), f.seq
        assert f.t_device_ns == f.seq * PERIOD_NS
    return offset


def test_realtime_stream_every_sample_in_order(ft_sim, wrench_of):
    def sat(k: int) -> np.ndarray:
        return np.array([False, k % 23 == 0, False, False, False, False])  # 23 divides the wrenches' period

    adapter, frames, stats, _ = _run(ft_sim, 2000, saturated=sat)
    undelivered = set(stats["damaged"])  # none unless the machine stalled the client past its socket buffer
    assert adapter.counters["records"] == stats["records"] == 2000 - len(undelivered)
    assert len(frames) == stats["records"]
    offset = _seqs_match_world(frames, wrench_of)
    assert all(bool(f.flags & WrenchFlag.SATURATED) == ((f.seq + offset) % 23 == 0) for f in frames)
    c = adapter.counters
    assert c["format_errors"] == c["device_errors"] == c["late"] == 0
    assert c["lost"] == len(undelivered) and c["packets_lost"] == len(undelivered)
    # the box's own count (rdt_sequence) against the emulator's: the receive count plus what was lost
    assert c["box_packets"] == stats["packets"] == c["packets"] + c["packets_lost"]


def test_buffered_mode_several_records_per_packet(ft_sim, wrench_of):
    scene, spec = ft_sim.device("ur5e-netft", "ft-rdt", mode="buffered", buffer=7)
    world = ft_sim.world(RATE, n_joints=6)
    emu = ft_sim.start_emulator(spec, scene, world, port=0, max_frames=700)
    bus = Bus()
    with make_adapter(spec, bus, emu.endpoint, scene=scene) as adapter:
        assert adapter.wait_connected(5.0)
        stats = ft_sim.wait_done(emu)
    frames = bus.history(adapter.topic)
    assert stats["packets"] == 100 and adapter.counters["packets"] == 100
    assert len(frames) == 700 and [f.seq for f in frames] == list(range(frames[0].seq, frames[0].seq + 700))
    _seqs_match_world(frames, wrench_of)
    # the records of one packet arrive together; their device times still say when each was sampled
    assert len({f.t_host_ns for f in frames}) == 100


def test_every_fault_counted_nothing_corrupted(ft_sim, wrench_of):
    faults = {"drop": 0.01, "duplicate": 0.01, "reorder": 0.01, "truncate": 0.01, "delay": 0.002, "delay_ms": 2,
              "stall_s": [[1.0, 0.03]]}  # the stream runs from the connect (< 1 s after ready) for 1.4 s
    adapter, frames, stats, _ = _run(ft_sim, 10000, faults=faults, seed=5)
    injected = stats["faults"]
    assert all(injected.get(k, 0) >= 10 for k in ("drop", "duplicate", "reorder", "truncate", "stalled"))
    offset = _seqs_match_world(frames, wrench_of)
    c = adapter.counters
    assert c["format_errors"] == injected["truncate"]
    assert c["duplicates"] == injected["duplicate"]
    assert c["late"] == injected["reorder"]
    seqs = [f.seq for f in frames]
    assert seqs == sorted(set(seqs))  # never a duplicate, never out of order
    missing = set(range(seqs[0], seqs[-1] + 1)) - set(seqs)
    assert len(missing) == c["lost"]
    # lost: exactly the samples of the dropped, truncated and stalled packets and of the late (reordered) ones
    assert (stats["boot_sample"] - offset) % 2001 == 0
    undelivered = {n - stats["boot_sample"] for n in stats["damaged"] + stats["fault_at"]["reorder"]}
    assert missing == undelivered & set(range(seqs[0], seqs[-1] + 1))
    flagged = {f.seq for f in frames if f.flags & WrenchFlag.SEQ_GAP}
    assert flagged == {n + 1 for n in missing if n + 1 not in missing}


def test_status_word_errors_flag_frames_and_send_events(ft_sim):
    adapter, frames, stats, events = _run(ft_sim, 3000, status_error_records=[[1000, 500]])
    bad = [f for f in frames if f.flags & WrenchFlag.DEVICE_ERROR]
    boot = stats["boot_sample"]
    first = frames[0].seq + boot  # the world sample of the stream's record 0 (the adapter's first frame)
    assert {f.seq + boot for f in bad} == {first + i for i in range(1000, 1500)} - set(stats["damaged"])
    assert adapter.counters["device_errors"] == len(bad) > 0
    seqs = [f.seq for f in bad]
    assert seqs == list(range(seqs[0], seqs[-1] + 1))  # one window
    kinds = [(e.kind, e.message) for e in events if "status word" in e.message]
    assert [k for k, _ in kinds] == ["error", "recovered"] and "0x80000000" in kinds[0][1]


def test_reboot_restarts_the_sequences_and_the_adapter_starts_the_stream_again(ft_sim, wait_for):
    scene, spec = ft_sim.device("ur5e-netft", "ft-rdt", stale_after_s=0.05)
    world = ft_sim.world(RATE, n_joints=6)
    emu = ft_sim.start_emulator(spec, scene, world, port=0, faults={"disconnect_at_s": 0.5, "reconnect_after_s": 0.3})
    bus = Bus()
    events = bus.subscribe(EVENTS_DEVICE, maxsize=None)
    adapter = make_adapter(spec, bus, emu.endpoint, scene=scene, silence_s=0.2)
    with adapter:
        assert adapter.wait_connected(5.0)
        assert wait_for(lambda: adapter.counters["seq_resets"] >= 1 and adapter.counters["frames"] > 6000, 15.0)
    kinds = [e.kind for e in events.drain()]
    assert kinds.count("connect") >= 2 and "disconnect" in kinds and "stale" in kinds
    stats = ft_sim.read_stats(emu)
    assert stats["reboots"] == 1
    frames = bus.history(adapter.topic)
    seqs = [f.seq for f in frames]
    assert seqs == sorted(set(seqs))  # the bus seq keeps increasing across the box's restart
    after = [f for f in frames if f.flags & WrenchFlag.CLOCK_SUSPECT and f.seq > seqs[0] + 100]
    assert after  # the device clock restarted with the box: suspect until realigned


def test_plain_socket_client_from_atis_description_reads_the_same_counts(ft_sim, wrench_of):
    """What a Net F/T user's own script does (ATI's RDT description, no code of ours): the calibration
    page over HTTP, a start request, 36-byte records in network byte order. Its counts for each
    ft_sequence are the counts the adapter decodes for that sample of the box (the world's sample
    ft_sequence + boot offset, which the adapter's frames give), axis for axis."""
    scene, spec = ft_sim.device("ur5e-netft", "ft-rdt")
    world = ft_sim.world(RATE, n_joints=6)
    emu = ft_sim.start_emulator(spec, scene, world, port=0)
    host, port, http_port = emu.endpoint["host"], emu.endpoint["port"], emu.endpoint["http_port"]
    with urllib.request.urlopen(f"http://{host}:{http_port}/netftapi2.xml", timeout=2.0) as page:
        xml = ET.fromstring(page.read())
    per_count = np.array([1 / float(xml.findtext("cfgcpf"))] * 3 + [1 / float(xml.findtext("cfgcpt"))] * 3)
    assert (xml.findtext("scfgfu"), xml.findtext("scfgtu")) == ("N", "Nm")
    theirs: dict[int, tuple[int, ...]] = {}
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.settimeout(2.0)
        s.sendto(struct.pack("!HHI", 0x1234, 0x0002, 500), (host, port))  # 500 records, real-time
        while len(theirs) < 500:
            data = s.recv(1024)
            assert len(data) == 36
            _rdt_seq, ft_seq, status, *counts = struct.unpack("!3I6i", data)
            theirs[ft_seq] = tuple(counts)
    bus = Bus()
    with make_adapter(spec, bus, emu.endpoint, scene=scene) as adapter:
        assert adapter.wait_connected(5.0)
        frames = bus.subscribe(adapter.topic, maxsize=None)
        got = [frames.get(timeout=2.0) for _ in range(300)]
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:  # the box keeps a bias: set it last
        s.settimeout(2.0)
        s.sendto(struct.pack("!HHI", 0x1234, 0x0042, 0), (host, port))  # set software bias, then 100 records
        s.sendto(struct.pack("!HHI", 0x1234, 0x0002, 100), (host, port))
        biased = {}
        while len(biased) < 100:
            _rdt_seq, ft_seq, status, *counts = struct.unpack("!3I6i", s.recv(1024))
            biased[ft_seq] = np.array(counts)
    offset = _seqs_match_world(got, wrench_of)
    ours = {f.seq: np.asarray(f.wrench) / per_count for f in got}  # the counts the adapter decoded
    for ft_seq, counts in theirs.items():
        assert np.array_equal(counts, np.round(wrench_of(ft_seq + offset) / per_count).astype(int)), ft_seq
    for ft_seq, counts in ours.items():
        assert np.allclose(counts, np.round(wrench_of(ft_seq + offset) / per_count), atol=1e-6), ft_seq
    # biased: every record less the same counts (the reading when the bias was set), of a sample before them
    less = {tuple(np.round(wrench_of(k + offset) / per_count).astype(int) - c) for k, c in biased.items()}
    assert len(less) == 1 and min(biased) > max(ours) > max(theirs)


def test_bad_requests_are_counted_by_the_box_and_it_serves_the_next_good_one(ft_sim, wait_for):
    scene, spec = ft_sim.device("ur5e-netft", "ft-rdt")
    world = ft_sim.world(RATE, n_joints=6)
    emu = ft_sim.start_emulator(spec, scene, world, port=0)
    box = (emu.endpoint["host"], emu.endpoint["port"])
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.settimeout(2.0)
        for bad in (struct.pack("!HHI", 0x4321, 2, 0), struct.pack("!HHI", 0x1234, 0x0099, 0), b"\x12\x34\x00\x02",
                    struct.pack("!HHI", 0x1234, 2, 0) + b"\x00"):
            s.sendto(bad, box)
        s.sendto(struct.pack("!HHI", 0x1234, 0x0002, 3), box)
        assert [len(s.recv(1024)) for _ in range(3)] == [36] * 3
    assert wait_for(lambda: ft_sim.read_stats(emu).get("bad_requests") == 4, 5.0)


class _FakeBox:
    """The test plays the box: a calibration page over HTTP and an RDT socket it writes by hand."""

    def __init__(self, page: bytes) -> None:
        class Page(http.server.BaseHTTPRequestHandler):
            def do_GET(self) -> None:  # noqa: N802
                self.send_response(200)
                self.end_headers()
                self.wfile.write(page)

            def log_message(self, *args) -> None:
                pass

        self.http = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Page)
        threading.Thread(target=self.http.serve_forever, daemon=True).start()
        self.udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.udp.bind(("127.0.0.1", 0))
        self.udp.settimeout(5.0)
        self.endpoint = {"host": "127.0.0.1", "port": self.udp.getsockname()[1],
                         "http_port": self.http.server_address[1]}

    def close(self) -> None:
        self.http.shutdown()
        self.http.server_close()
        self.udp.close()


def _record(rdt_seq: int, ft_seq: int, status: int = 0) -> bytes:
    return struct.pack("!3I6i", rdt_seq, ft_seq, status, 100_000, -200_000, 300_000, 1_000_000, 0, -1_000_000)


def test_bad_datagrams_and_status_errors_never_crash_the_reader(wait_for):
    """Short and long datagrams are format errors, a status word with error bits flags its frame (and an
    event), and the reader goes on with the next good record."""
    box = _FakeBox(b"<netft><cfgcpf>100000</cfgcpf><cfgcpt>1000000</cfgcpt><scfgfu>N</scfgfu>"
                   b"<scfgtu>N-m</scfgtu><comrdtrate>7000</comrdtrate></netft>")
    bus = Bus()
    events = bus.subscribe(EVENTS_DEVICE, maxsize=None)
    try:
        adapter = make_adapter(DeviceSpec("ft", "ft-rdt", "udp", None, {}), bus, box.endpoint, silence_s=None)
        with adapter:
            request, client = box.udp.recvfrom(64)
            assert request == struct.pack("!HHI", 0x1234, 0x0002, 0)
            for data in (_record(1, 10), _record(2, 11)[:35], _record(3, 12) + b"\x00", _record(4, 13) * 2,
                         b"", _record(5, 14, status=0x80000000), _record(6, 15), _record(6, 15), _record(5, 14)):
                box.udp.sendto(data, client)
            assert wait_for(lambda: adapter.counters["packets"] == 9, 5.0)
            assert adapter.connected.is_set()
        stop = box.udp.recv(64)
        assert stop == struct.pack("!HHI", 0x1234, 0x0000, 0)
    finally:
        box.close()
    frames = bus.history("wrench/ft")
    assert [f.seq for f in frames] == [10, 14, 15]
    assert np.allclose(frames[0].wrench, [1.0, -2.0, 3.0, 1.0, 0.0, -1.0])
    assert frames[0].t_device_ns == 10 * PERIOD_NS  # no rate_hz param: the box's comrdtrate
    assert [bool(f.flags & WrenchFlag.DEVICE_ERROR) for f in frames] == [False, True, False]
    assert frames[1].flags & WrenchFlag.SEQ_GAP
    c = adapter.counters
    assert (c["format_errors"], c["duplicates"], c["late"], c["device_errors"], c["lost"]) == (4, 1, 1, 1, 3)
    said = [e.kind for e in events.drain() if "status word" in e.message]
    assert said == ["error", "recovered"]


@pytest.mark.parametrize(("options", "field"), [
    ({"calibration_xml": "<netft><cfgcpf>100000</cfgcpf><cfgcpt>"}, "/netftapi2.xml"),
    ({"calibration_fields": {"cfgcpt": "ten"}}, "cfgcpt"),
    ({"calibration_fields": {"comrdtrate": "1000"}}, "comrdtrate: the box says 1000, the scene 7000"),
    ({"calibration_fields": {"cfgcpf": "1000000"}, "calapi_fields": {"calcpf": "1000000"}},
     "calcpf: the box says 1000000, the scene 100000"),
    ({"calibration_fields": {"cfgcpf": "1000000"}, "calapi": False, "tcp": False},
     "cfgcpf: the box says 1000000, the scene 100000"),
    ({"calibration_fields": {"cfgcpf": "1000000"}, "calapi": False}, "cfgcpf: the configuration's counts per SI unit "
     "(1e+06) are not the calibration's (100000, TCP 49151 READCALINFO countsPerForce/countsPerTorque)"),
    ({"calibration_fields": {"cfgcpf": "1000000"}}, "cfgcpf: the configuration's counts per SI unit (1e+06) are not "
     "the calibration's (100000, /netftcalapi.xml calcpf/calcpt)"),
    ({"calapi_fields": {"scalfu": "lbf"}, "calibration_fields": {"scfgfu": "lbf"}},
     "calcpf: the box says 22480.89430997105 per SI unit (its unit is lbf), the scene 100000"),
])
def test_a_bad_or_disagreeing_calibration_page_is_named_and_nothing_is_published(ft_sim, wait_event, options, field):
    scene, spec = ft_sim.device("ur5e-netft", "ft-rdt", counts_per_force=100000)
    world = ft_sim.world(RATE, n_joints=6)
    emu = ft_sim.start_emulator(spec, scene, world, port=0, **options)
    bus = Bus()
    events = bus.subscribe(EVENTS_DEVICE, maxsize=None)
    with make_adapter(spec, bus, emu.endpoint, scene=scene) as adapter:
        ev = wait_event(events, "reconnecting", 5.0)
        assert not adapter.connected.is_set()
    assert field in ev.message
    assert not bus.history(adapter.topic)
    assert ft_sim.read_stats(emu).get("records", 0) == 0


def test_scene_counts_without_the_calibration_page(wait_for):
    """read_calibration=false: the scene's counts per N and N m decode (the box's page, malformed here,
    is never read)."""
    box = _FakeBox(b"<netft><cfgcpf>")
    bus = Bus()
    params = {"read_calibration": False, "counts_per_force": 1000.0, "counts_per_torque": 2000.0, "rate_hz": 1000.0}
    try:
        with make_adapter(DeviceSpec("ft", "ft-rdt", "udp", None, params), bus, box.endpoint) as adapter:
            _, client = box.udp.recvfrom(64)
            box.udp.sendto(_record(1, 5), client)
            assert wait_for(lambda: adapter.counters["frames"] == 1, 5.0)
    finally:
        box.close()
    (frame,) = bus.history("wrench/ft")
    assert np.allclose(frame.wrench, [100.0, -200.0, 300.0, 500.0, 0.0, -500.0])
    assert frame.t_device_ns == 5 * 1_000_000


def test_a_box_biased_by_another_program_is_read_unbiased(ft_sim, wrench_of, wait_for):
    """Another program set the box's software bias (RDT 0x0042) and left: the box subtracts that reading from
    every record. The adapter reads the bias from the box's page (setbias), adds it back, publishes the
    unbiased wrench (the world's, exactly) and says so when it connects; the box keeps its bias."""
    scene, spec = ft_sim.device("ur5e-netft", "ft-rdt")
    world = ft_sim.world(RATE, n_joints=6)
    emu = ft_sim.start_emulator(spec, scene, world, port=0)
    host, port, http_port = emu.endpoint["host"], emu.endpoint["port"], emu.endpoint["http_port"]

    def page_bias() -> tuple[int, ...]:
        with urllib.request.urlopen(f"http://{host}:{http_port}/netftapi2.xml", timeout=2.0) as page:
            return tuple(int(c) for c in ET.fromstring(page.read()).findtext("setbias").split())

    assert page_bias() == (0,) * 6
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.sendto(struct.pack("!HHI", 0x1234, 0x0042, 0), (host, port))
    assert wait_for(lambda: any(page_bias()), 5.0)
    bias = page_bias()
    bus = Bus()
    events = bus.subscribe(EVENTS_DEVICE, maxsize=None)
    with make_adapter(spec, bus, emu.endpoint, scene=scene) as adapter:
        assert adapter.wait_connected(5.0)
        frames = bus.subscribe(adapter.topic, maxsize=None)
        got = [frames.get(timeout=2.0) for _ in range(300)]
    assert adapter.box is not None and adapter.box.bias == bias
    assert adapter.box.source == "/netftcalapi.xml calcpf/calcpt"
    _seqs_match_world(got, wrench_of)  # every frame the world's wrench, not the biased one
    connect = next(e for e in events.drain() if e.kind == "connect")
    assert f"box_bias {list(bias)}" in connect.message
    assert page_bias() == bias  # left as the other program set it
