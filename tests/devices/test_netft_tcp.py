"""The emulated Net F/T box's TCP interface on port 49151 of its own address: byte-for-byte replies as ATI's
manual fixes them, a client in a process of its own that reads the calibration there as the ROS 2 driver of
netft_utils does, several clients at once, and clients that send garbage or leave mid-command."""
from __future__ import annotations

import json
import socket
import struct
import subprocess
import sys
import textwrap
import threading
import time
import urllib.request
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from ftc_hw.bus import Bus
from ftc_hw.devices.registry import make_adapter

pytestmark = [pytest.mark.realtime, pytest.mark.timeout(90)]
RATE = 1000.0
WRENCH = np.array([12.5, -3.25, 40.0, 0.375, -1.5, 0.0625])
COUNTS = (1_250_000, -325_000, 4_000_000, 375_000, -1_500_000, 62_500)  # 1e5 per N, 1e6 per N m


def _box(ft_sim, **options):
    scene, spec = ft_sim.device("ur5e-netft", "ft-rdt")
    world = ft_sim.world(RATE, n_joints=6, fn=lambda _k: WRENCH)
    emu = ft_sim.start_emulator(spec, scene, world, **options)
    return scene, spec, emu


def _connect(emu) -> socket.socket:
    s = socket.create_connection((emu.endpoint["host"], emu.endpoint["tcp_port"]), timeout=3.0)
    return s


def _recv(s: socket.socket, n: int) -> bytes:
    return s.recv(n, socket.MSG_WAITALL)


def _nothing_more(s: socket.socket, wait: float = 0.3) -> bytes:
    s.settimeout(wait)
    try:
        return s.recv(100)
    except TimeoutError:
        return b"timeout"


def _calapi(emu) -> dict[str, str]:
    url = f"http://{emu.endpoint['host']}:{emu.endpoint['http_port']}/netftcalapi.xml"
    with urllib.request.urlopen(url, timeout=2.0) as page:
        return {el.tag: el.text or "" for el in ET.fromstring(page.read())}


ROS2_LIKE = textwrap.dedent("""
    # What netft_utils' ROS 2 driver does before it streams: connect to TCP 49151 of the box, send READCALINFO
    # (command 1 and 19 zero bytes), read_some up to 25 bytes, require exactly 24, unpack them big-endian.
    import json, socket, struct, sys
    s = socket.create_connection((sys.argv[1], 49151), timeout=5.0)
    s.sendall(bytes([1]) + bytes(19))
    reply = s.recv(25)
    header, fu, tu, cpf, cpt, *factors = struct.unpack(">HBBII6H", reply)
    print(json.dumps({"length": len(reply), "header": header, "force_units": fu, "torque_units": tu,
                      "cpf": cpf, "cpt": cpt, "factors": factors}))
""")


def test_a_client_of_its_own_reads_the_calibration_our_adapter_reads_from_the_pages(ft_sim):
    scene, spec, emu = _box(ft_sim)
    assert emu.endpoint["tcp_port"] == 49151 and "tcp_port_note" not in emu.endpoint
    run = subprocess.run([sys.executable, "-c", ROS2_LIKE, emu.endpoint["host"]], capture_output=True, text=True,
                         timeout=60)
    assert run.returncode == 0, run.stderr
    theirs = json.loads(run.stdout)
    assert (theirs["length"], theirs["header"], theirs["force_units"], theirs["torque_units"]) == (24, 0x1234, 2, 3)
    cal = _calapi(emu)
    assert (theirs["cpf"], theirs["cpt"]) == (int(cal["calcpf"]), int(cal["calcpt"]))  # the pages' counts per unit
    assert (cal["scalfu"], cal["scaltu"], cal["calfu"], cal["caltu"]) == ("N", "Nm", "2", "3")
    with make_adapter(spec, Bus(), emu.endpoint, scene=scene) as adapter:
        assert adapter.wait_connected(5.0)
        ours = adapter.calibration
    assert (ours.counts_per_force, ours.counts_per_torque) == (theirs["cpf"], theirs["cpt"])
    time.sleep(0.3)  # the emulator's stats file is rewritten every 0.1 s
    stats = ft_sim.read_stats(emu)
    assert (stats["tcp_commands"], stats["tcp_bad_commands"], stats["tcp_aborted"]) == (1, 0, 0)


def test_each_command_answers_byte_for_byte(ft_sim):
    _, _, emu = _box(ft_sim)
    time.sleep(0.2)  # a few samples made: the box has a reading
    with _connect(emu) as s:
        s.sendall(b"\x01" + bytes(19))  # READCALINFO
        cal = _recv(s, 24)
        header, fu, tu, cpf, cpt, *factors = struct.unpack(">HBBII6H", cal)
        assert (header, fu, tu, cpf, cpt) == (0x1234, 2, 3, 100_000, 1_000_000)
        assert cal[:12] == b"\x12\x34\x02\x03\x00\x01\x86\xa0\x00\x0f\x42\x40"
        s.sendall(b"\x00" + bytes(19))  # READFT: 16 bytes, the 32-bit counts over the scale factors
        ft = _recv(s, 16)
        assert ft == struct.pack(">HH6h", 0x1234, 0, *(round(c / f) for c, f in zip(COUNTS, factors, strict=True)))
        s.sendall(b"\x02\x03\x01" + struct.pack(">6h", 100, 0, 0, 0, 0, 9000) + bytes(5))  # WRITETRANSFORM: refused
        assert _recv(s, 4) == b"\x12\x34\x02\x01"
        s.sendall(b"\x03\x00\x02\x01\x01" + struct.pack(">h", 500) + bytes(13))  # WRITETHRESHOLD: refused
        assert _recv(s, 4) == b"\x12\x34\x03\x01"
        s.sendall(b"\x03\x40\x02\x01\x01" + bytes(15))  # a write out of range: status 1, the connection goes on
        assert _recv(s, 4) == b"\x12\x34\x03\x01"
        s.sendall(b"\x00" + bytes(17) + b"\x00\x03")  # READFT with bias and latch reset: the reading is now zero
        assert _recv(s, 16) == b"\x12\x34" + bytes(14)
        assert _nothing_more(s) == b"timeout"  # one reply per command, nothing else (and 0.3 s for the stats)
    stats = ft_sim.read_stats(emu)
    assert (stats["tcp_commands"], stats["tcp_refused"], stats["tcp_bad_commands"], stats["latch_resets"]) == (
        5, 2, 1, 1)


def test_several_clients_at_once_and_bad_ones_never_stop_the_server(ft_sim):
    _, _, emu = _box(ft_sim)
    garbage = _connect(emu)
    garbage.sendall(b"\xff" * 20)  # an unknown command: no answer, the connection closed
    assert _nothing_more(garbage, 2.0) == b""
    garbage.close()
    for partial in (b"\x01\x00\x00", b"\x00" * 19):  # closed mid-command
        with _connect(emu) as s:
            s.sendall(partial)
    reset = _connect(emu)
    reset.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    reset.sendall(b"\x01")
    reset.close()  # RST mid-command
    results: list[bytes] = []

    def client() -> None:
        with _connect(emu) as s:
            for _ in range(20):
                s.sendall(b"\x01" + bytes(19))
                results.append(_recv(s, 24))

    threads = [threading.Thread(target=client) for _ in range(4)]
    held = [_connect(emu) for _ in range(3)]  # idle connections do not block the others
    for t in threads:
        t.start()
    for t in threads:
        t.join(30)
    for s in held:
        s.close()
    assert len(results) == 80 and len(set(results)) == 1 and results[0][:2] == b"\x12\x34"
    time.sleep(0.3)
    stats = ft_sim.read_stats(emu)
    assert stats["tcp_bad_commands"] == 1 and stats["tcp_aborted"] == 3 and stats["tcp_commands"] == 80
    assert stats["tcp_connections"] == 1 + 2 + 1 + 4 + 3


def test_where_49151_is_taken_the_interface_moves_to_a_free_port_and_says_so(ft_sim, capfd):
    host = "127.0.0.8"
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as squatter:
        squatter.bind((host, 49151))
        squatter.listen()
        _, _, emu = _box(ft_sim, host=host, port=0, http_port=0)
        note = emu.endpoint["tcp_port_note"]
        assert emu.endpoint["tcp_port"] != 49151 and f"{host}:49151" in note and str(emu.endpoint["tcp_port"]) in note
        assert note in capfd.readouterr().err
        with _connect(emu) as s:
            s.sendall(b"\x01" + bytes(19))
            assert _recv(s, 24)[:2] == b"\x12\x34"


@pytest.mark.parametrize("tcp", [True, False])
def test_without_the_calibration_page_our_adapter_asks_readcalinfo(ft_sim, tcp):
    """A box without /netftcalapi.xml (404): the adapter reads the calibration over TCP 49151, as the ROS 2
    driver does; a box without the TCP interface either: the configuration's cfgcpf/cfgcpt. The same counts
    per unit either way, and the same wrench."""
    scene, spec, emu = _box(ft_sim, calapi=False, tcp=tcp)
    assert (emu.endpoint["tcp_port"] is not None) == tcp
    bus = Bus()
    with make_adapter(spec, bus, emu.endpoint, scene=scene) as adapter:
        assert adapter.wait_connected(5.0)
        frames = bus.subscribe(adapter.topic, maxsize=None)
        wrench = frames.get(timeout=2.0).wrench
        source, cal, c = adapter.box.source, adapter.calibration, dict(adapter.counters)
    assert (cal.counts_per_force, cal.counts_per_torque, cal.force_unit, cal.torque_unit) == (100_000, 1_000_000,
                                                                                             "N", "Nm")
    assert np.allclose(wrench, WRENCH, atol=1e-5)
    if tcp:
        assert source == "TCP 49151 READCALINFO countsPerForce/countsPerTorque"
        assert (c["calibration_tcp"], c.get("calinfo_errors", 0), c.get("calibration_fallback", 0)) == (1, 0, 0)
        time.sleep(0.3)  # the emulator's stats file is rewritten every 0.1 s
        assert ft_sim.read_stats(emu)["tcp_commands"] == 1
    else:
        assert source == "/netftapi2.xml cfgcpf/cfgcpt"
        assert (c.get("calibration_tcp", 0), c["calinfo_errors"], c["calibration_fallback"]) == (0, 1, 1)
