"""One ROS context, node and executor thread per process, shared by every ROS adapter (and publisher) in
it: :func:`acquire` hands out the node, started on first use; :func:`release` stops it when the last
user is gone. Each user makes its own subscriptions and publishers on the node.

The executor is rclpy's ``EventsExecutor`` (platform-notes: half the subscriber's CPU of the
``SingleThreadedExecutor`` at 1 kHz), its callbacks run in one daemon thread named ``ros-executor``: they
must only hand messages over, never compute. The node follows the user's ROS environment
(``ROS_DOMAIN_ID``, ``ROS_AUTOMATIC_DISCOVERY_RANGE``), as every ROS node does.
"""
from __future__ import annotations

import atexit
import os
import threading
from typing import Any

from .availability import require_ros

require_ros("a ROS device (ros-joint-state, ros-wrench) or ftc ros")

import rclpy  # noqa: E402 - after the check that names what to install
from rclpy.context import Context  # noqa: E402
from rclpy.experimental import EventsExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.signals import SignalHandlerOptions  # noqa: E402

_lock = threading.Lock()
_state: dict[str, Any] = {}  # context, node, executor, thread, users


def _spin(executor: Any, context: Context) -> None:
    while context.ok():
        try:
            executor.spin_once(timeout_sec=0.1)
        except Exception:  # noqa: BLE001 - shutting down (the context or executor gone): nothing to spin
            if not context.ok():
                return
            raise


def acquire(name: str = "ftc_hw", *, unique: bool = True) -> Node:
    """The process's node, its executor spinning; made on first use, named ``<name>_<pid>`` (``unique``) or
    ``name``: a later caller shares the node whatever name it asks."""
    with _lock:
        if not _state:
            context = Context()
            # no signal handlers of rclpy's: ftc's commands handle Ctrl-C and SIGTERM (closing adapters, writing
            # the summary); rclpy's would shut the context down under them and pass the signal on at its time
            rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
            node = Node(f"{name}_{os.getpid()}" if unique else name, context=context)
            executor = EventsExecutor(context=context)
            executor.add_node(node)
            thread = threading.Thread(target=_spin, args=(executor, context), name="ros-executor", daemon=True)
            _state.update(context=context, node=node, executor=executor, thread=thread, users=0)
            thread.start()
            atexit.register(_at_exit)
        _state["users"] += 1
        return _state["node"]


def release() -> None:
    """One user fewer; the last one shuts the node, the executor and the context down."""
    with _lock:
        if not _state:
            return
        _state["users"] -= 1
        if _state["users"] > 0:
            return
        state = dict(_state)
        _state.clear()
    _shutdown(state)


def _at_exit() -> None:
    """The executor's thread stopped before the interpreter goes (a C++ thread alive then aborts it)."""
    with _lock:
        state = dict(_state)
        _state.clear()
    if state:
        _shutdown(state)


def _shutdown(state: dict[str, Any]) -> None:
    atexit.unregister(_at_exit)
    state["context"].shutdown()
    state["thread"].join(timeout=2.0)
    state["executor"].shutdown(timeout_sec=1.0)
    state["node"].destroy_node()
