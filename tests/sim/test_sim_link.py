"""The world's link: commands as JSON datagrams from emulator processes, woken on, bad input counted; the
joint ring's records read by name."""
from __future__ import annotations

import multiprocessing as mp
import socket

import numpy as np
import pytest

from ftc_hw.sim_devices.link import (
    Command,
    CommandLinkError,
    EmulatorSide,
    JointRecord,
    LinkInfo,
    NoFTRingError,
    WorldLink,
)

pytestmark = pytest.mark.compute  # computes only (nothing timed): runs with the others on every core

GOAL = Command("arm", "goal", q=(0.1, -1.05, 0.35 + 1e-12, 0.7), extra={"t_rx_ns": 123})


def _send(info: LinkInfo, commands: list[Command]) -> None:
    side = EmulatorSide(info)
    try:
        for c in commands:
            side.send(c)
    finally:
        side.close()


def test_commands_from_another_process_arrive_whole_and_in_order():
    link = WorldLink(4)
    try:
        sent = [GOAL, Command("arm", "torque", on=False), Command("ur", "stop")]
        p = mp.get_context("spawn").Process(target=_send, args=(link.info, sent))
        p.start()
        got: list[Command] = []
        while len(got) < len(sent):
            assert link.wait_commands(30.0), "no command arrived"
            got += link.drain_commands()
        p.join(10)
        assert [(c.source, c.kind, c.q, c.on, c.extra) for c in got] == \
            [(c.source, c.kind, c.q, c.on, c.extra) for c in sent]  # floats exact through JSON
        assert all(c.t_sent_ns > 0 for c in got)
        assert not link.wait_commands(0.0) and link.drain_commands() == []
    finally:
        link.close()


def test_malformed_datagrams_are_counted_and_dropped():
    link = WorldLink(2)
    try:
        s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        for junk in (b"not json", b"[1, 2]", b'{"kind": "goal"}', b'{"source": "a", "kind": "goal", "q": "xy"}'):
            s.sendto(junk, link.command_path)
        s.sendto(GOAL.encode(), link.command_path)
        s.close()
        got = link.drain_commands()
        assert [c.q for c in got] == [GOAL.q]
        assert link.bad_commands == 4
    finally:
        link.close()


def test_a_closed_world_is_a_typed_error():
    link = WorldLink(2)
    side = EmulatorSide(link.info)
    link.close()
    with pytest.raises(CommandLinkError):
        side.send(GOAL)
    side.close()


def test_a_joint_record_reads_back_by_name_what_the_world_wrote():
    link = WorldLink(3)
    side = EmulatorSide(link.info)
    try:
        assert side.joint_state() is None
        q, qd, qdd, current, tau, tau_j = (np.arange(3) + 10.0 * k for k in range(1, 7))
        link.publish_joints(1.25, q, qd, qdd, current, tau, tau_j)
        rec = side.joint_reader().ring.read(0)
        assert rec.shape == (1 + JointRecord.width(3),)
        for got in (JointRecord.from_row(rec, 3), side.joint_state()):
            assert got.t == 1.25 and isinstance(got.t, float)
            for name, want in zip(("q", "qd", "qdd", "current", "tau", "tau_j"), (q, qd, qdd, current, tau, tau_j),
                                  strict=True):
                assert np.array_equal(getattr(got, name), want), name
    finally:
        side.close()
        link.close()


def test_a_world_without_an_f_t_sensor_has_no_f_t_ring_and_says_so():
    link = WorldLink(2, ft=False)
    side = EmulatorSide(link.info)
    try:
        assert link.info.ft_ring is None and link.ft is None and side.ft is None
        with pytest.raises(NoFTRingError, match="no F/T sensor"):
            side.ft_reader()
        z = np.zeros(2)
        link.publish_joints(0.5, z, z, z, z, z, z + 1.0)
        assert np.array_equal(side.joint_state().tau_j, [1.0, 1.0])
    finally:
        side.close()
        link.close()
