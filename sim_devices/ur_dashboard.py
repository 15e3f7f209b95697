"""The UR dashboard server's commands (e-Series, PolyScope 5) as data: each command's words, its replies
and their source, and what it does to the emulated controller.

A line is matched case-insensitively against the commands' words (the longest first, so ``load
installation x`` is not a program load); what follows the words is the command's argument. Each
command's ``act`` changes the controller's state and names the outcome; the reply is that outcome's
template in the table, filled from the argument and the controller's state. A line that matches no
command gets UR's ``could not understand: '<line>'``. Sources (``sim_devices/SOURCES.md``, "UR
dashboard"): DOC, UR's "Dashboard Server e-Series, port 29999" and "Dashboard Server, port 29999"
(CB3) pages; URCL, UR's client library (UniversalRobots/Universal_Robots_Client_Library,
``src/ur/dashboard_client_implementation_g5.cpp``, the reply patterns it checks); RTDE, ur_rtde's
``dashboard_client.cpp`` (what its DashboardClient sends and accepts).
"""
from __future__ import annotations

import contextlib
import socket
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from . import ur_data as D

if TYPE_CHECKING:
    from .ur import Controller

DOC, URCL, RTDE = "UR dashboard doc", "UR client library", "ur_rtde"
OK, FAIL = "ok", "fail"
UNKNOWN = "could not understand: '{line}'"
OPERATIONAL_MODES = ("manual", "automatic")


@dataclass(frozen=True)
class DashboardCommand:
    """One command: ``words`` (lower case), whether it takes an argument, its replies by outcome
    (``str.format`` templates over ``arg`` and the controller's ``fields``), what it does, its sources."""

    words: str
    replies: dict[str, str]
    act: Callable[[Controller, str], str] = lambda ctl, arg: OK  # a query: changes nothing
    takes_arg: bool = False
    sources: tuple[str, ...] = (DOC, URCL)
    closes: bool = False  # the server closes the connection after the reply
    notes: str = ""


# -- what the commands do ------------------------------------------------------------------------------------
def _power_on(ctl: Controller, arg: str) -> str:
    if ctl.robot_mode == D.ROBOT_POWER_OFF:
        ctl.robot_mode = D.ROBOT_IDLE
    return OK


def _power_off(ctl: Controller, arg: str) -> str:
    if ctl.robot_mode != D.ROBOT_POWER_OFF:
        ctl.robot_mode = D.ROBOT_POWER_OFF
        ctl.runtime = D.RUNTIME_STOPPED
        ctl.halt()  # the brakes hold the arm
    return OK


def _brake_release(ctl: Controller, arg: str) -> str:
    if ctl.robot_mode == D.ROBOT_IDLE:
        ctl.robot_mode = D.ROBOT_RUNNING
    return OK


def _play(ctl: Controller, arg: str) -> str:
    if ctl.robot_mode != D.ROBOT_RUNNING or ctl.safety_mode != D.SAFETY_NORMAL or not ctl.program:
        return FAIL
    ctl.play()
    return OK


def _pause(ctl: Controller, arg: str) -> str:
    if ctl.runtime != D.RUNTIME_PLAYING:
        return FAIL
    ctl.runtime = D.RUNTIME_PAUSED
    ctl.halt()
    return OK


def _stop(ctl: Controller, arg: str) -> str:
    if ctl.runtime == D.RUNTIME_STOPPED:
        return FAIL
    ctl.runtime = D.RUNTIME_STOPPED
    ctl.halt()
    return OK


def _load(ctl: Controller, arg: str) -> str:
    if not arg.lower().endswith(".urp"):
        return "not found"  # the emulated controller holds .urp programs only
    if ctl.runtime != D.RUNTIME_STOPPED:  # loading stops the running program
        ctl.runtime = D.RUNTIME_STOPPED
        ctl.halt()
    ctl.program_path = arg if arg.startswith("/") else f"/programs/{arg}"
    return OK


def _load_installation(ctl: Controller, arg: str) -> str:
    if not arg.lower().endswith(".installation"):
        return "not found"
    ctl.installation = arg
    return OK


def _set_operational_mode(ctl: Controller, arg: str) -> str:
    if arg.lower() not in OPERATIONAL_MODES:
        return FAIL
    ctl.operational_mode = arg.upper()
    return OK


def _clear_operational_mode(ctl: Controller, arg: str) -> str:
    return OK  # the dashboard lets go of the mode; the mode itself stays


def _unlock_protective_stop(ctl: Controller, arg: str) -> str:
    if ctl.safety_mode == D.SAFETY_PROTECTIVE_STOP:
        ctl.safety_mode = D.SAFETY_NORMAL
    return OK


def _restart_safety(ctl: Controller, arg: str) -> str:
    ctl.safety_mode = D.SAFETY_NORMAL
    return _power_off(ctl, arg)  # the robot is powered off after a safety restart


def _add_to_log(ctl: Controller, arg: str) -> str:
    if not arg:
        return FAIL
    ctl.log.append(arg)
    return OK


def _popup(ctl: Controller, arg: str) -> str:
    ctl.popup = arg
    return OK


def _close_popup(ctl: Controller, arg: str) -> str:
    ctl.popup = None
    return OK


def _running(ctl: Controller, arg: str) -> str:
    return "true" if ctl.runtime == D.RUNTIME_PLAYING else "false"


def _loaded(ctl: Controller, arg: str) -> str:
    return OK if ctl.program else FAIL


def _refuse(ctl: Controller, arg: str) -> str:
    return FAIL


def fields(ctl: Controller) -> dict[str, str]:
    """The controller's state as the replies' template fields."""
    return {
        "robot_mode": D.ROBOT_MODES[ctl.robot_mode],
        "safety_mode": D.SAFETY_MODES[ctl.safety_mode],
        "program_state": D.RUNTIME_NAMES.get(ctl.runtime, "STOPPED"),
        "program": ctl.program or "<unnamed>",
        "program_path": ctl.program_path,
        "version": "{}.{}.{}.{}".format(*ctl.version),
        "serial": ctl.serial,
        "model": ctl.model,
        "operational_mode": ctl.operational_mode,
        "remote": str(ctl.remote_control).lower(),
    }


# -- the table -------------------------------------------------------------------------------------------------
COMMANDS: tuple[DashboardCommand, ...] = (
    DashboardCommand("load installation", {OK: "Loading installation: {arg}", "not found": "File not found: {arg}"},
                     _load_installation, takes_arg=True),
    DashboardCommand("load", {OK: "Loading program: {arg}", "not found": "File not found: {arg}"}, _load,
                     takes_arg=True, sources=(DOC, URCL, RTDE)),
    DashboardCommand("play", {OK: "Starting program", FAIL: "Failed to execute: play"}, _play,
                     sources=(DOC, URCL, RTDE)),
    DashboardCommand("stop", {OK: "Stopped", FAIL: "Failed to execute: stop"}, _stop, sources=(DOC, URCL, RTDE)),
    DashboardCommand("pause", {OK: "Pausing program", FAIL: "Failed to execute: pause"}, _pause,
                     sources=(DOC, URCL, RTDE)),
    DashboardCommand("quit", {OK: "Disconnected"}, closes=True, sources=(DOC, URCL, RTDE)),
    DashboardCommand("shutdown", {OK: "Shutting down"}, _power_off, sources=(DOC, URCL, RTDE),
                     notes="the emulated controller powers the arm off and keeps serving"),
    DashboardCommand("running", {"true": "Program running: true", "false": "Program running: false"}, _running,
                     sources=(DOC, URCL, RTDE)),
    DashboardCommand("robotmode", {OK: "Robotmode: {robot_mode}"}, sources=(DOC, URCL, RTDE)),
    DashboardCommand("get loaded program", {OK: "Loaded program: {program_path}", FAIL: "No program loaded"},
                     _loaded, sources=(DOC, URCL, RTDE)),
    DashboardCommand("popup", {OK: "showing popup"}, _popup, takes_arg=True, sources=(DOC, URCL, RTDE)),
    DashboardCommand("close popup", {OK: "closing popup"}, _close_popup, sources=(DOC, URCL, RTDE)),
    DashboardCommand("close safety popup", {OK: "closing safety popup"}, sources=(DOC, URCL, RTDE)),
    DashboardCommand("addtolog", {OK: "Added log message", FAIL: "No log message to add"}, _add_to_log,
                     takes_arg=True, sources=(DOC, URCL, RTDE)),
    DashboardCommand("isprogramsaved", {OK: "true {program}"}, sources=(DOC, URCL, RTDE),
                     notes="documented lower case; ur_rtde 1.6.5's isProgramSaved() looks for 'True'"),
    DashboardCommand("programstate", {OK: "{program_state} {program}"}, sources=(DOC, URCL, RTDE)),
    DashboardCommand("polyscopeversion", {OK: "URSoftware {version} (emulated)"}, sources=(DOC, URCL, RTDE)),
    DashboardCommand("version", {OK: "{version}"}),
    DashboardCommand("set operational mode",
                     {OK: "Operational mode '{arg}' is set", FAIL: "Failed setting operational mode '{arg}'"},
                     _set_operational_mode, takes_arg=True),
    DashboardCommand("get operational mode", {OK: "{operational_mode}"}),
    DashboardCommand("clear operational mode",
                     {OK: "No longer controlling the operational mode. Current operational mode: "
                          "'{operational_mode}'."}, _clear_operational_mode),
    DashboardCommand("power on", {OK: "Powering on"}, _power_on, sources=(DOC, URCL, RTDE)),
    DashboardCommand("power off", {OK: "Powering off"}, _power_off, sources=(DOC, URCL, RTDE)),
    DashboardCommand("brake release", {OK: "Brake releasing"}, _brake_release, sources=(DOC, URCL, RTDE)),
    DashboardCommand("safetymode", {OK: "Safetymode: {safety_mode}"}, sources=(DOC, URCL, RTDE)),
    DashboardCommand("safetystatus", {OK: "Safetystatus: {safety_mode}"}, sources=(DOC, URCL, RTDE)),
    DashboardCommand("unlock protective stop", {OK: "Protective stop releasing"}, _unlock_protective_stop,
                     sources=(DOC, URCL, RTDE)),
    DashboardCommand("restart safety", {OK: "Restarting safety"}, _restart_safety, sources=(DOC, URCL, RTDE)),
    DashboardCommand("is in remote control", {OK: "{remote}"}, sources=(DOC, URCL, RTDE)),
    DashboardCommand("get serial number", {OK: "{serial}"}, sources=(DOC, URCL, RTDE)),
    DashboardCommand("get robot model", {OK: "{model}"}, sources=(DOC, URCL, RTDE)),
    DashboardCommand("generate flight report", {FAIL: "Error: flight reports are not available on an emulated "
                                                      "controller"}, _refuse, takes_arg=True,
                     notes="a documented refusal ('Error: <message>'): the emulator has no report to give"),
    DashboardCommand("generate support file", {FAIL: "Error: support files are not available on an emulated "
                                                     "controller"}, _refuse, takes_arg=True,
                     notes="a documented refusal ('Error: <message>')"),
    DashboardCommand("savelog", {OK: "Log saved to disk"}),
)
_BY_LENGTH = sorted(COMMANDS, key=lambda c: len(c.words), reverse=True)


def match(line: str) -> tuple[DashboardCommand, str] | None:
    """The command a line (stripped) names and its argument, or None."""
    low = line.lower()
    for cmd in _BY_LENGTH:
        if low == cmd.words:
            return cmd, ""
        if cmd.takes_arg and low.startswith(cmd.words + " "):
            return cmd, line[len(cmd.words) + 1:].strip()
    return None


def answer(ctl: Controller, line: str) -> tuple[str, bool]:
    """The reply to one stripped line and whether the server closes the connection after it; the
    caller holds the controller's lock."""
    found = match(line)
    if found is None:
        return UNKNOWN.format(line=line), False
    cmd, arg = found
    outcome = cmd.act(ctl, arg)
    return cmd.replies[outcome].format(arg=arg, **fields(ctl)), cmd.closes


# -- the line protocol ---------------------------------------------------------------------------------------
MAX_LINE = 4096  # bytes; a longer line is answered as not understood (its start quoted) and skipped
_QUOTE = 200  # characters of an overlong line quoted in the reply


def serve_connection(conn: socket.socket, handle: Callable[[str], tuple[str, bool]], welcome: str) -> None:
    """One client: the welcome line, then a reply line per ``\\n``-terminated line (``\\r`` and blanks
    around it dropped, bytes that are not UTF-8 replaced). A line without its newline waits for it; a client
    gone mid-line, or one that stops reading, ends the connection quietly."""
    buf = b""
    skipping = False  # inside an overlong line already answered
    with contextlib.suppress(OSError), conn:
        conn.sendall((welcome + "\n").encode())
        while True:
            chunk = conn.recv(4096)
            if not chunk:
                return
            buf += chunk
            while True:
                raw, nl, rest = buf.partition(b"\n")
                if not nl:
                    if len(buf) > MAX_LINE:
                        if not skipping:
                            conn.sendall((_overlong(buf) + "\n").encode())
                        skipping, buf = True, b""
                    break
                buf = rest
                if skipping or len(raw) > MAX_LINE:
                    if not skipping:
                        conn.sendall((_overlong(raw) + "\n").encode())
                    skipping = False
                    continue
                reply, close = handle(raw.decode("utf-8", errors="replace").strip())
                conn.sendall((reply + "\n").encode())
                if close:
                    return


def _overlong(raw: bytes) -> str:
    return UNKNOWN.format(line=raw[:_QUOTE].decode("utf-8", errors="replace").strip() + "...")
