"""A listening TCP socket on a loopback address with an accept thread: the UR and Franka emulators'
command servers."""
from __future__ import annotations

import contextlib
import socket
import threading
from typing import Any


def drop_session(lock: threading.Lock, sessions: list, s: Any) -> None:
    """A session's end: marked closed, out of its server's ``sessions``, its socket closed."""
    s.closed = True
    with lock:
        if s in sessions:
            sessions.remove(s)
    with contextlib.suppress(OSError):
        s.sock.close()


class Listener:
    """A listening TCP socket on a loopback address and an accept thread calling ``on_client``."""

    def __init__(self, address: str, port: int, on_client: Any, name: str) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.sock.bind((address, port))
        self.sock.listen(8)
        self.on_client = on_client
        threading.Thread(target=self._accept, name=name, daemon=True).start()

    def _accept(self) -> None:
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self.on_client(conn)

    def close(self) -> None:
        """Stop listening (the shutdown wakes the accept thread, so the port is free at once)."""
        with contextlib.suppress(OSError):
            self.sock.shutdown(socket.SHUT_RDWR)
        self.sock.close()
