"""Emulated servers bind loopback addresses only: a device emulator never listens on a real network."""
from __future__ import annotations

import ipaddress


def check_loopback(address: str) -> str:
    """``address`` if it is a loopback IP address (127.0.0.x, ::1); ValueError otherwise."""
    try:
        ip = ipaddress.ip_address(address)
    except ValueError:
        raise ValueError(f"address {address!r} is not an IP address") from None
    if not ip.is_loopback:
        raise ValueError(f"refusing to bind {address}: the emulator binds loopback addresses only (127.0.0.x)")
    return address
