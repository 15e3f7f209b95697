"""The Net F/T emulator as clients we did not write see it: the third-party PyPI client ``netft`` (module
``NetFT``, Cameron Devine) in a process of its own, and the replies ATI's protocol fixes, byte for byte:
the pages' documented fields, the 36-byte records, the commands, bad input (sim_devices/SOURCES.md)."""
from __future__ import annotations

import json
import socket
import struct
import subprocess
import sys
import textwrap
import time
import urllib.error
import urllib.request
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from ftc_hw.bus import Bus
from ftc_hw.devices.registry import make_adapter

pytestmark = [pytest.mark.realtime, pytest.mark.timeout(90)]
RATE = 7000.0  # the scene sensor's rate, which the emulator serves as comrdtrate
WRENCH = np.array([12.5, -3.25, 40.0, 0.375, -1.5, 0.0625])  # exact in counts (1e5 per N, 1e6 per N m)
COUNTS = (1_250_000, -325_000, 4_000_000, 375_000, -1_500_000, 62_500)


def _constant(_k: int) -> np.ndarray:
    return WRENCH


def _box(ft_sim, **options):
    scene, spec = ft_sim.device("ur5e-netft", "ft-rdt")
    world = ft_sim.world(RATE, n_joints=6, fn=_constant)
    emu = ft_sim.start_emulator(spec, scene, world, **options)
    return scene, spec, emu


def _get(emu, page: str) -> tuple[int, bytes]:
    url = f"http://{emu.endpoint['host']}:{emu.endpoint['http_port']}{page}"
    try:
        with urllib.request.urlopen(url, timeout=2.0) as answer:
            return answer.status, answer.read()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read()


def _fields(page: bytes) -> dict[str, str]:
    root = ET.fromstring(page)
    return {el.tag: (el.text or "") for el in root}


THIRD_PARTY = textwrap.dedent("""
    import json, sys
    import NetFT
    sensor = NetFT.Sensor(sys.argv[1])          # RDT port 49152: hard-coded by the client
    sensor.sock.settimeout(5.0)
    single = [sensor.getMeasurement() for _ in range(3)]   # start (2) with count 1, one record each
    sensor.startStreaming(handler=False)                   # start (2), count 0: until stopped
    stream = [sensor.receive() for _ in range(200)]
    sensor.stopStreaming()
    print(json.dumps({"single": single, "stream": stream}))
""")


def test_the_third_party_netft_client_reads_what_our_adapter_reads(ft_sim):
    """PyPI ``netft`` 2.0.1 in its own process, at the box's address (port 49152 is all it knows): its raw
    counts, scaled by the box's own calibration page, equal our adapter's values within one count."""
    scene, spec, emu = _box(ft_sim)
    host = emu.endpoint["host"]
    assert emu.endpoint["port"] == 49152  # where every client looks (and the pages on 80, unless said)
    assert emu.endpoint["http_port"] == 80 or "http_port_note" in emu.endpoint
    run = subprocess.run([sys.executable, "-c", THIRD_PARTY, host], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    theirs = json.loads(run.stdout)
    cal = _fields(_get(emu, "/netftcalapi.xml")[1])
    per_count = np.array([1 / float(cal["calcpf"])] * 3 + [1 / float(cal["calcpt"])] * 3)
    bus = Bus()
    with make_adapter(spec, bus, emu.endpoint, scene=scene) as adapter:
        assert adapter.wait_connected(5.0)
        frames = bus.subscribe(adapter.topic, maxsize=None)
        ours = np.array([frames.get(timeout=2.0).wrench for _ in range(200)])
    for counts in theirs["single"] + theirs["stream"]:
        assert tuple(counts) == COUNTS
        assert np.all(np.abs(np.asarray(counts) * per_count - ours) <= per_count + 1e-12)
    assert ft_sim.read_stats(emu)["bad_requests"] == 0


def test_the_pages_have_the_documented_fields_per_index_and_404_for_the_rest(ft_sim):
    _, _, emu = _box(ft_sim)
    status, page = _get(emu, "/netftapi2.xml")
    assert status == 200 and ET.fromstring(page).tag == "netft"
    sys_ = _fields(page)
    for key in ("runstat", "runft", "setbias", "setcfgsel", "cfgnam", "cfgcalsel", "cfgcpf", "cfgcpt", "scfgfu",
                "scfgtu", "cfgfu", "cfgtu", "cfgmr", "comrdte", "comrdtrate", "comrdtbsiz", "netip"):
        assert key in sys_, key
    got = (sys_["runstat"], sys_["setcfgsel"], sys_["cfgcalsel"], sys_["comrdte"])
    assert got == ("0x00000000", "0", "0", "Enabled")
    assert (sys_["scfgfu"], sys_["cfgfu"], sys_["scfgtu"], sys_["cfgtu"]) == ("N", "2", "Nm", "3")
    got = (sys_["cfgcpf"], sys_["cfgcpt"], sys_["comrdtrate"], sys_["comrdtbsiz"])
    assert got == ("100000", "1000000", "7000", "10")
    assert sys_["netip"] == emu.endpoint["host"] and sys_["setbias"] == "0 0 0 0 0 0"
    assert tuple(int(c) for c in sys_["runft"].split()) == COUNTS
    # ATI's demo: index 0 for setcfgsel, then the active configuration's page; the others are other configurations
    active = _fields(_get(emu, f"/netftapi2.xml?index={sys_['setcfgsel']}")[1])
    other = _fields(_get(emu, "/netftapi2.xml?index=5")[1])
    assert active["cfgnam"] == sys_["cfgnam"] and other["cfgnam"] == "Config 6" != active["cfgnam"]
    status, page = _get(emu, f"/netftcalapi.xml?index={sys_['cfgcalsel']}")
    assert status == 200 and ET.fromstring(page).tag == "netftCalibration"
    cal = _fields(page)
    assert {k: cal[k] for k in ("calcpf", "calcpt", "scalfu", "scaltu", "calfu", "caltu")} == {
        "calcpf": "100000", "calcpt": "1000000", "scalfu": "N", "scaltu": "Nm", "calfu": "2", "caltu": "3"}
    assert cal["calsn"] and cal["calpn"] and len(cal["calmr"].split(";")) == 6
    # ATI's Java demo: the ranges split on ';' and each parsed as a number (a page it cannot parse stops it)
    assert [float(r) for r in sys_["cfgmr"].split(";")] == [660.0, 660.0, 1980.0, 60.0, 60.0, 60.0]
    for bad in ("/netftapi2.xml?index=16", "/netftapi2.xml?index=x", "/netftcalapi.xml?index=1", "/netft.xml",
                "/../etc/passwd", "/netftapi2.xml?index=-1"):
        assert _get(emu, bad)[0] == 404, bad
    for garbage in (b"GARBAGE\r\n\r\n", b"GET /netftapi2.xml HTTP/9.9\r\n\r\n", b"\x00\xff" * 40 + b"\r\n\r\n"):
        with socket.create_connection((emu.endpoint["host"], emu.endpoint["http_port"]), timeout=2.0) as c:
            c.sendall(garbage)  # not HTTP: an error page (400, or 505 for the version), then the connection closes
            answer = b"".join(iter(lambda: c.recv(4096), b""))
            assert b"Error code: 400" in answer or b"Error code: 505" in answer, answer
    assert _get(emu, "/netftapi2.xml")[0] == 200  # the server goes on after bad requests
    time.sleep(0.25)
    stats = ft_sim.read_stats(emu)
    assert stats["page_errors"] == 6 and stats["pages"] == 5


def _request(command: int, count: int = 0) -> bytes:
    return struct.pack("!HHI", 0x1234, command, count)


def _datagrams(s: socket.socket, quiet: float = 0.3) -> list[bytes]:
    """Every datagram until ``quiet`` s without one."""
    out = []
    s.settimeout(quiet)
    while True:
        try:
            out.append(s.recv(4096))
        except TimeoutError:
            return out


def test_rdt_replies_byte_for_byte_and_bad_input_counted(ft_sim):
    """The request is 8 bytes (0x1234, command, count), a record 36: uint32 rdt_sequence (1 for a stream's first
    packet), uint32 ft_sequence, uint32 status, six int32 counts, network byte order."""
    _, _, emu = _box(ft_sim)
    box = (emu.endpoint["host"], emu.endpoint["port"])
    record = struct.Struct("!3I6i")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.sendto(_request(0x0001, 1), box)  # ATI's Java library: loop-driven output, one record
        (one,) = _datagrams(s)
        assert len(one) == 36
        rdt, ft, status, *counts = record.unpack(one)
        assert (rdt, status, tuple(counts)) == (1, 0, COUNTS)
        assert one == struct.pack("!3I6i", 1, ft, 0, *COUNTS)
        s.sendto(_request(0x0002, 3), box)  # real-time: a record per datagram, consecutive samples
        got = [record.unpack(d) for d in _datagrams(s)]
        assert [g[0] for g in got] == [1, 2, 3] and np.diff([g[1] for g in got]).tolist() == [1, 1]
        s.sendto(_request(0x0003, 20), box)  # buffered: comrdtbsiz (10) records per datagram
        got = _datagrams(s)
        assert [len(d) for d in got] == [360, 360]
        assert [record.unpack_from(d, 0)[0] for d in got] == [1, 2]
        for command in (0x0004, 0x0041):  # multi-unit: refused; reset threshold latch: taken. Neither answers
            s.sendto(_request(command), box)
            assert _datagrams(s) == []
        for bad in (b"", b"\x12\x34\x00\x02", _request(0x0002) + b"\x00", struct.pack("!HHI", 0x4321, 2, 1),
                    _request(0x0099, 1), _request(0x0005, 1)):
            s.sendto(bad, box)
        assert _datagrams(s) == []
        s.sendto(_request(0x0042), box)  # set software bias: what follows is less this reading (all of it here)
        s.sendto(_request(0x0002, 1), box)
        (biased,) = _datagrams(s)
        assert record.unpack(biased)[3:] == (0,) * 6
    time.sleep(0.25)
    stats = ft_sim.read_stats(emu)
    assert (stats["bad_requests"], stats["refused"], stats["latch_resets"]) == (6, 1, 1)
    assert _fields(_get(emu, "/netftapi2.xml")[1])["setbias"] == " ".join(map(str, COUNTS))


def test_where_port_80_is_taken_the_pages_move_to_a_free_port_and_say_so(ft_sim, capfd):
    host = "127.0.0.9"
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as squatter:
        try:
            squatter.bind((host, 80))
            squatter.listen()
        except OSError:  # no right to bind port 80 here: the emulator has none either, the same fallback
            pass
        scene, spec, emu = _box(ft_sim, host=host, port=0)
        note = emu.endpoint["http_port_note"]
        assert emu.endpoint["http_port"] != 80 and f"{host}:80" in note and str(emu.endpoint["http_port"]) in note
        assert note in capfd.readouterr().err  # said on the emulator's stderr, not only in the endpoint
        assert _get(emu, "/netftapi2.xml")[0] == 200
        with make_adapter(spec, Bus(), emu.endpoint, scene=scene) as adapter:  # the endpoint tells our adapter
            assert adapter.wait_connected(5.0)


def test_ftc_sim_puts_the_box_at_the_given_address(tmp_path):
    """``ftc sim --address ft=127.0.0.7``: RDT on 127.0.0.7:49152 and the pages on 127.0.0.7:80, where a
    client that knows only the box's address finds them."""
    proc = subprocess.Popen([sys.executable, "-m", "ftc_hw", "sim", "ur5e-netft", "--scenario", "static-pokes",
                             "--duration", "60", "--address", "ft=127.0.0.7"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        first = json.loads(proc.stdout.readline())
        (ft,) = [d for d in first["devices"] if d["name"] == "ft"]
        assert (ft["host"], ft["port"]) == ("127.0.0.7", 49152), ft
        assert ft["http_port"] == 80 or "http_port_note" in ft, ft  # 80 unless this host forbids it, and says so
        with urllib.request.urlopen(f"http://127.0.0.7:{ft['http_port']}/netftapi2.xml", timeout=5.0) as page:
            assert _fields(page.read())["netip"] == "127.0.0.7"
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.settimeout(5.0)
            s.sendto(_request(0x0002, 1), ("127.0.0.7", 49152))
            assert len(s.recv(64)) == 36
    finally:
        proc.send_signal(2)
        try:
            proc.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()
