"""The Net F/T box's TCP interface, as the RDT emulator (:mod:`ftc_hw.sim_devices.netft_rdt`) runs it: a
server on TCP port 49151 of the box's address (a free port, said, where 49151 cannot be bound), a thread
per connection, any number of clients at once. Each connection is a sequence of 20-byte commands, each
answered (or not) before the next is read; the bytes: :mod:`ftc_hw.codecs.netft_tcp`; what each follows:
``sim_devices/SOURCES.md``.

A command the codec rejects: a write (WRITETRANSFORM, WRITETHRESHOLD) with a field out of range gets the
write response with status 1, the connection goes on; anything else (an unknown command code) gets no
answer and the connection is closed (20-byte framing cannot be trusted after it); both counted in
``tcp_bad_commands``. A client that closes or resets mid-command is counted in ``tcp_aborted``. The
server itself never stops for a client.
"""
from __future__ import annotations

import contextlib
import socket
import socketserver
from collections.abc import Callable
from typing import Any

from ftc_hw.codecs.netft_tcp import (
    COMMAND_SIZE,
    TCP_PORT,
    TcpCommand,
    TcpCommandError,
    decode_command,
    encode_write_reply,
)

from .netft_web import bind_server

IDLE_S = 600.0  # a connection silent this long is closed (its thread ends)
COUNTS = ("tcp_connections", "tcp_commands", "tcp_bad_commands", "tcp_aborted", "tcp_refused")


class TcpServer(socketserver.ThreadingTCPServer):
    allow_reuse_address = True
    daemon_threads = True


def bind_tcp(host: str, port: int | None, answer: Callable[[TcpCommand], bytes | None], counts: dict[str, int],
             fallback: bool = True) -> tuple[TcpServer, str]:
    """The box's TCP interface on ``host``: ``port`` when given (bound or OSError), else 49151, else
    (``fallback``) a free port, with the sentence that says so (empty when on 49151 or as given).
    ``answer(command)`` gives the reply's bytes (None: no reply); ``counts`` gets :data:`COUNTS`."""
    for key in COUNTS:
        counts.setdefault(key, 0)
    handler = _handler(answer, counts)
    return bind_server(lambda p: TcpServer((host, p), handler), port, TCP_PORT, fallback,
                       f"the TCP interface to {host}:{TCP_PORT} ({{}}); it is on port {{}} instead, where clients "
                       f"looking at port {TCP_PORT} (the calibration info) do not find it")


def _read_command(sock: socket.socket) -> bytes:
    """The next 20 bytes; fewer when the client closed before sending them all."""
    data = b""
    while len(data) < COMMAND_SIZE:
        chunk = sock.recv(COMMAND_SIZE - len(data))
        if not chunk:
            break
        data += chunk
    return data


def _handler(answer: Callable[[TcpCommand], bytes | None], counts: dict[str, int]) -> type:
    class Connection(socketserver.BaseRequestHandler):
        def handle(self) -> None:
            counts["tcp_connections"] += 1
            sock: socket.socket = self.request
            sock.settimeout(IDLE_S)
            try:
                self._serve(sock)
            except OSError:  # reset, broken pipe, idle: that client's loss, never the server's
                counts["tcp_aborted"] += 1

        def _serve(self, sock: socket.socket) -> None:
            while True:
                data = _read_command(sock)
                if not data:
                    return  # closed between commands: a normal end
                try:
                    command = decode_command(data)
                except TcpCommandError as exc:
                    if len(data) < COMMAND_SIZE:
                        counts["tcp_aborted"] += 1  # closed mid-command
                        return
                    counts["tcp_bad_commands"] += 1
                    if exc.command is None:
                        return  # out of step: close
                    sock.sendall(encode_write_reply(exc.command, 1))
                    continue
                counts["tcp_commands"] += 1
                reply = answer(command)
                if reply is not None:
                    sock.sendall(reply)

        def finish(self) -> None:
            with contextlib.suppress(OSError):
                self.request.shutdown(socket.SHUT_RDWR)

    return Connection


def close_tcp(server: Any) -> None:
    if server is not None:
        with contextlib.suppress(Exception):
            server.shutdown()
            server.server_close()
