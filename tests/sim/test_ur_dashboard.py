"""The emulated UR dashboard server: UR's documented replies byte for byte over a plain socket, bad input
(unknown commands, garbage, an overlong line, a line without its newline, a client gone mid-line), and
ur_rtde's own DashboardClient, in a process of its own, against the emulator in a world."""
from __future__ import annotations

import json
import socket
import subprocess
import sys
import textwrap
import time

import pytest

from ftc_hw.scene import load_scene
from ftc_hw.sim_devices import ur_data as D
from ftc_hw.sim_devices.host import WorldHost
from ftc_hw.sim_devices.link import Command
from ftc_hw.sim_devices.ur import Controller, DashboardServer
from ftc_hw.sim_devices.ur_dashboard import COMMANDS, MAX_LINE, match

PLAIN_ADDRESS = "127.0.0.47"  # a dashboard server alone (no world)
WORLD_ADDRESS = "127.0.0.46"  # the UR emulator in a world
WELCOME = b"Connected: Universal Robots Dashboard Server\n"


class FakeWorld:
    def __init__(self) -> None:
        self.sent: list[Command] = []

    def send(self, cmd: Command) -> None:
        self.sent.append(cmd)


@pytest.fixture
def server():
    world = FakeWorld()
    ctl = Controller((5, 9, 0, 0), world, "arm", "20205500001", "UR5")
    srv = DashboardServer(ctl, PLAIN_ADDRESS, D.DASHBOARD_PORT)
    yield ctl, world
    srv.close()


class Line:
    """A plain dashboard connection."""

    def __init__(self) -> None:
        self.sock = socket.create_connection((PLAIN_ADDRESS, D.DASHBOARD_PORT), timeout=2.0)
        self.buf = b""

    def read(self) -> bytes:
        while b"\n" not in self.buf:
            chunk = self.sock.recv(4096)
            if not chunk:
                raise ConnectionError("closed")
            self.buf += chunk
        line, _, self.buf = self.buf.partition(b"\n")
        return line + b"\n"

    def ask(self, raw: bytes) -> bytes:
        self.sock.sendall(raw)
        return self.read()

    def __enter__(self) -> Line:
        assert self.read() == WELCOME
        return self

    def __exit__(self, *exc: object) -> None:
        self.sock.close()


# command -> the documented reply, in order from the emulator's start (powered, RUNNING, the scenario
# playing); sources in sim_devices/SOURCES.md ("UR dashboard")
REPLIES: list[tuple[str, str]] = [
    ("PolyscopeVersion", "URSoftware 5.9.0.0 (emulated)"),
    ("version", "5.9.0.0"),
    ("get serial number", "20205500001"),
    ("get robot model", "UR5"),
    ("robotmode", "Robotmode: RUNNING"),
    ("safetymode", "Safetymode: NORMAL"),
    ("safetystatus", "Safetystatus: NORMAL"),
    ("programState", "PLAYING ftc-scenario.urp"),
    ("running", "Program running: true"),
    ("get loaded program", "Loaded program: /programs/ftc-scenario.urp"),
    ("is in remote control", "true"),
    ("isProgramSaved", "true ftc-scenario.urp"),
    ("get operational mode", "AUTOMATIC"),
    ("set operational mode manual", "Operational mode 'manual' is set"),
    ("get operational mode", "MANUAL"),
    ("set operational mode automatic", "Operational mode 'automatic' is set"),
    ("clear operational mode", "No longer controlling the operational mode. Current operational mode: 'AUTOMATIC'."),
    ("load installation default.installation", "Loading installation: default.installation"),
    ("pause", "Pausing program"),
    ("programState", "PAUSED ftc-scenario.urp"),
    ("running", "Program running: false"),
    ("pause", "Failed to execute: pause"),
    ("play", "Starting program"),
    ("stop", "Stopped"),
    ("programState", "STOPPED ftc-scenario.urp"),
    ("stop", "Failed to execute: stop"),
    ("load other.urp", "Loading program: other.urp"),
    ("get loaded program", "Loaded program: /programs/other.urp"),
    ("programState", "STOPPED other.urp"),
    ("load missing.txt", "File not found: missing.txt"),
    ("popup hello operator", "showing popup"),
    ("close popup", "closing popup"),
    ("close safety popup", "closing safety popup"),
    ("addToLog a line for the log", "Added log message"),
    ("addToLog", "No log message to add"),
    ("saveLog", "Log saved to disk"),
    ("unlock protective stop", "Protective stop releasing"),
    ("power off", "Powering off"),
    ("robotmode", "Robotmode: POWER_OFF"),
    ("play", "Failed to execute: play"),
    ("power on", "Powering on"),
    ("robotmode", "Robotmode: IDLE"),
    ("brake release", "Brake releasing"),
    ("robotmode", "Robotmode: RUNNING"),
    ("play", "Starting program"),
    ("programState", "PLAYING other.urp"),
    ("restart safety", "Restarting safety"),
    ("robotmode", "Robotmode: POWER_OFF"),
    ("generate flight report controller", "Error: flight reports are not available on an emulated controller"),
    ("generate support file /tmp", "Error: support files are not available on an emulated controller"),
    ("shutdown", "Shutting down"),
    ("hello", "could not understand: 'hello'"),
    ("quit", "Disconnected"),
]


@pytest.mark.compute
def test_documented_replies_byte_for_byte(server):
    ctl, world = server
    with Line() as c:
        got = [(cmd, c.ask(cmd.encode() + b"\n")) for cmd, _ in REPLIES]
        assert got == [(cmd, reply.encode() + b"\n") for cmd, reply in REPLIES]
        assert c.sock.recv(16) == b""  # quit closed the connection
    # pause, play, stop, power off, play, restart safety; the load (of a stopped program) and the shutdown
    # (of a powered-off arm) halt nothing
    assert [cmd.kind for cmd in world.sent] == ["stop", "resume", "stop", "stop", "resume", "stop"]
    assert (ctl.installation, ctl.log, ctl.popup) == ("default.installation", ["a line for the log"], None)


@pytest.mark.compute
def test_every_command_of_the_table_is_in_the_byte_table():
    asked = {match(cmd)[0].words for cmd, _ in REPLIES if match(cmd) is not None}
    assert asked == {c.words for c in COMMANDS}
    assert match("load installation x.installation")[0].words == "load installation"  # not a program load
    assert match("LOAD other.urp") == (match("load other.urp")[0], "other.urp")  # words in any case


@pytest.mark.compute
def test_bad_input_gets_the_documented_reply_and_never_a_crash(server):
    ctl, world = server
    with Line() as c:
        assert c.ask(b"hello world\n") == b"could not understand: 'hello world'\n"
        assert c.ask(b"get operational\n") == b"could not understand: 'get operational'\n"
        assert c.ask(b"\xff\xfe\x00abc\n") == "could not understand: '\ufffd\ufffd\x00abc'\n".encode()
        assert c.ask(b"\n") == b"could not understand: ''\n"
        assert c.ask(b"robotmode\r\n") == b"Robotmode: RUNNING\n"
        # an overlong line: one reply quoting its start, then the connection serves on
        long_line = b"x" * (3 * MAX_LINE)
        c.sock.sendall(long_line[:MAX_LINE + 100])
        assert c.read() == b"could not understand: '" + b"x" * 200 + b"...'\n"
        assert c.ask(long_line[MAX_LINE + 100:] + b"\nrobotmode\n") == b"Robotmode: RUNNING\n"
        assert c.ask(b"y" * (MAX_LINE + 1) + b"\n") == b"could not understand: '" + b"y" * 200 + b"...'\n"
        # a line without its newline waits for it
        c.sock.sendall(b"programSt")
        c.sock.settimeout(0.3)
        with pytest.raises(TimeoutError):
            c.sock.recv(64)
        c.sock.settimeout(2.0)
        assert c.ask(b"ate\n") == b"PLAYING ftc-scenario.urp\n"
    # a client gone mid-line: its half command is not run, and the server serves the next client
    gone = socket.create_connection((PLAIN_ADDRESS, D.DASHBOARD_PORT), timeout=2.0)
    gone.sendall(b"sto")
    gone.close()
    time.sleep(0.1)
    with Line() as c:
        assert c.ask(b"programState\n") == b"PLAYING ftc-scenario.urp\n"
    assert world.sent == [] and ctl.halts == 0


CLIENT = textwrap.dedent("""
    import json, sys
    import dashboard_client

    d = dashboard_client.DashboardClient(sys.argv[1])
    out = []

    def call(name, *args):
        try:
            out.append([name, *args, getattr(d, name)(*args)])
        except Exception as exc:
            out.append([name, *args, "raised: " + str(exc)])

    def raw(line):
        d.send(line + "\\n")
        out.append(["send", line, d.receive()])

    d.connect()
    for name in ("polyscopeVersion", "getRobotModel", "getSerialNumber", "robotmode", "safetymode",
                 "safetystatus", "programState", "getLoadedProgram", "running", "isInRemoteControl",
                 "isProgramSaved"):
        call(name)
    raw("isProgramSaved")
    raw("version")
    raw("get operational mode")
    raw("set operational mode manual")
    raw("get operational mode")
    raw("set operational mode automatic")
    raw("clear operational mode")
    raw("load installation default.installation")
    for step in (("pause",), ("programState",), ("running",), ("play",), ("stop",), ("programState",),
                 ("stop",), ("loadURP", "other.urp"), ("getLoadedProgram",), ("programState",), ("play",),
                 ("programState",), ("addToLog", "from ur_rtde"), ("popup", "hello"), ("closePopup",),
                 ("closeSafetyPopup",), ("unlockProtectiveStop",), ("powerOff",), ("robotmode",),
                 ("powerOn",), ("robotmode",), ("brakeRelease",), ("robotmode",), ("play",),
                 ("programState",)):
        call(*step)
    d.disconnect()
    print(json.dumps(out))
""")

EXPECTED = [
    ["polyscopeVersion", "5.9.0.0"],
    ["getRobotModel", "UR5"],
    ["getSerialNumber", "20205500001"],
    ["robotmode", "Robotmode: RUNNING"],
    ["safetymode", "Safetymode: NORMAL"],
    ["safetystatus", "Safetystatus: NORMAL"],
    ["programState", "PLAYING ftc-scenario.urp"],
    ["getLoadedProgram", "Loaded program: /programs/ftc-scenario.urp"],
    ["running", True],
    ["isInRemoteControl", True],
    # UR documents "true <program>" in lower case (so does UR's client library's pattern); ur_rtde 1.6.5's
    # isProgramSaved() looks for "True", so it says False for a saved program: the raw reply shows it
    ["isProgramSaved", False],
    ["send", "isProgramSaved", "true ftc-scenario.urp"],
    ["send", "version", "5.9.0.0"],
    ["send", "get operational mode", "AUTOMATIC"],
    ["send", "set operational mode manual", "Operational mode 'manual' is set"],
    ["send", "get operational mode", "MANUAL"],
    ["send", "set operational mode automatic", "Operational mode 'automatic' is set"],
    ["send", "clear operational mode",
     "No longer controlling the operational mode. Current operational mode: 'AUTOMATIC'."],
    ["send", "load installation default.installation", "Loading installation: default.installation"],
    ["pause", None],
    ["programState", "PAUSED ftc-scenario.urp"],
    ["running", False],
    ["play", None],
    ["stop", None],
    ["programState", "STOPPED ftc-scenario.urp"],
    ["stop", "raised: Failed to execute: stop"],
    ["loadURP", "other.urp", None],
    ["getLoadedProgram", "Loaded program: /programs/other.urp"],
    ["programState", "STOPPED other.urp"],
    ["play", None],
    ["programState", "PLAYING other.urp"],
    ["addToLog", "from ur_rtde", None],
    ["popup", "hello", None],
    ["closePopup", None],
    ["closeSafetyPopup", None],
    ["unlockProtectiveStop", None],
    ["powerOff", None],
    ["robotmode", "Robotmode: POWER_OFF"],
    ["powerOn", None],
    ["robotmode", "Robotmode: IDLE"],
    ["brakeRelease", None],
    ["robotmode", "Robotmode: RUNNING"],
    ["play", None],
    ["programState", "PLAYING other.urp"],
]


@pytest.mark.realtime  # against a world on the wall clock
def test_ur_rtde_dashboard_client_in_its_own_process():
    scene = load_scene("ur5e")
    with WorldHost(scene, "sweep", devices=["arm"], options={"arm": {"address": WORLD_ADDRESS}}, noise=False) as w:
        before = w.applied_count()
        done = subprocess.run([sys.executable, "-c", CLIENT, WORLD_ADDRESS], capture_output=True, text=True,
                              timeout=60)
        assert done.returncode == 0, done.stderr
        got = json.loads(done.stdout.strip().splitlines()[-1])
        assert got == EXPECTED
        time.sleep(0.2)
        # the world halted at pause, stop and power off, and went on at each play
        assert [a.kind for a in w.applied(before)] == ["stop", "resume", "stop", "resume", "stop", "resume"]


@pytest.mark.compute
def test_a_protective_stop_shows_and_is_unlocked():
    ctl = Controller((5, 9, 0, 0), FakeWorld(), "arm", "20205500001", "UR5")
    ctl.safety_mode = D.SAFETY_PROTECTIVE_STOP  # the world has no such stop: set as the controller would
    assert [ctl.dashboard(c) for c in ("safetystatus", "safetymode", "stop", "play")] == [
        "Safetystatus: PROTECTIVE_STOP", "Safetymode: PROTECTIVE_STOP", "Stopped", "Failed to execute: play"]
    assert ctl.dashboard("unlock protective stop") == "Protective stop releasing"
    assert [ctl.dashboard(c) for c in ("safetystatus", "play", "programState")] == [
        "Safetystatus: NORMAL", "Starting program", "PLAYING ftc-scenario.urp"]
