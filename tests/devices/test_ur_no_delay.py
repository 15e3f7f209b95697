"""``devices.ur.no_delay_to``: Nagle's algorithm turned off on this process's TCP connections to a peer that
a library (ur_rtde's IO interface) opened without exposing its socket; others left alone. Loopback sockets
only, no device."""
from __future__ import annotations

import socket

import pytest

from ftc_hw.devices.ur import no_delay_to

pytestmark = pytest.mark.compute


def _nodelay(s: socket.socket) -> int:
    return s.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY)


def test_only_the_connections_to_the_peer_get_no_delay():
    servers = [socket.create_server(("127.0.0.1", 0)) for _ in range(2)]
    clients = [socket.create_connection(s.getsockname()) for s in servers]
    try:
        assert [_nodelay(c) for c in clients] == [0, 0]  # the kernel's default: Nagle on
        host, port = servers[0].getsockname()
        assert no_delay_to(host, port) == 1
        assert _nodelay(clients[0]) and not _nodelay(clients[1])
        assert no_delay_to(host, port) == 0  # already off: nothing changed
        assert no_delay_to("127.0.0.1", 1) == 0  # no connection there
    finally:
        for s in clients + servers:
            s.close()
