"""The UR adapter reads the dashboard's documented replies and raises a typed error on anything else
(no controller: a scripted dashboard link)."""
from __future__ import annotations

import pytest

from ftc_hw.bus import Bus
from ftc_hw.devices.base import DeviceError
from ftc_hw.devices.ur import DashboardReplyError, URArm, parse_program_state

pytestmark = pytest.mark.compute  # no I/O


class ScriptedLink:
    """Answers each command from a table; records what was sent."""

    def __init__(self, replies: dict[str, str]) -> None:
        self.replies, self.sent = replies, []

    def command(self, text: str) -> str:
        self.sent.append(text)
        return self.replies[text]

    def close(self) -> None:
        pass


def arm(replies: dict[str, str]) -> URArm:
    a = URArm("arm", Bus(), "127.0.0.250")
    a.dashboard = ScriptedLink(replies)  # type: ignore[assignment]
    return a


@pytest.mark.parametrize("reply, parsed", [
    ("STOPPED ftc-scenario.urp", ("STOPPED", "ftc-scenario.urp")),
    ("PLAYING my program.urp", ("PLAYING", "my program.urp")),
    ("PAUSED <unnamed>", ("PAUSED", "<unnamed>")),
])
def test_program_state_in_the_documented_format(reply, parsed):
    assert parse_program_state(reply) == parsed


@pytest.mark.parametrize("reply", ["", "STOPPED", "stopped x.urp", "RUNNING x.urp",
                                   "could not understand: 'programState'", "Robotmode: RUNNING"])
def test_anything_else_is_a_typed_error(reply):
    with pytest.raises(DashboardReplyError, match="programState") as e:
        parse_program_state(reply)
    assert isinstance(e.value, DeviceError) and e.value.reply == reply


def test_stop_and_pause_accept_the_documented_replies():
    a = arm({"stop": "Stopped", "pause": "Pausing program"})
    a.stop()
    a.pause()
    assert (a.counters["stops"], a.counters["pauses"]) == (1, 1)


@pytest.mark.parametrize("command, state", [("stop", "STOPPED"), ("pause", "PAUSED"), ("pause", "STOPPED")])
def test_failed_to_execute_is_accepted_when_already_there(command, state):
    a = arm({command: f"Failed to execute: {command}", "programState": f"{state} x.urp"})
    getattr(a, command)()
    assert a.dashboard.sent == [command, "programState"]


@pytest.mark.parametrize("replies, match", [
    ({"stop": "Failed to execute: stop", "programState": "PLAYING x.urp"}, "'stop': unexpected reply"),
    ({"stop": "Failed to execute: stop", "programState": "could not understand: 'programState'"}, "programState"),
    ({"stop": "could not understand: 'stop'"}, "could not understand"),
    ({"stop": "Pausing program"}, "'stop': unexpected reply 'Pausing program'"),
])
def test_stop_raises_a_typed_error_on_other_replies(replies, match):
    a = arm(replies)
    with pytest.raises(DashboardReplyError, match=match):
        a.stop()
    assert a.counters["stops"] == 0
