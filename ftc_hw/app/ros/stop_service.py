"""The stop reflex on an arm whose driver is a ROS node: a ``std_srvs/Trigger`` service call, as
ur_robot_driver's dashboard client offers one (``/dashboard_client/stop``: the dashboard server's ``stop``,
which stops the running program and with it the arm). :class:`StopClient` calls it (the ``ros-joint-state``
adapter's ``stop()``, param ``stop_service``); :class:`StopServer` offers it (``ftc ros publish``, as the
driver would). Both live on the process's one node (:mod:`.context`); the call's response is awaited in the
caller's thread (the stop reflex's own, never the pipeline's) while the executor's thread delivers it.
"""
from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from ftc_hw.devices.base import DeviceError, DeviceIOError

from .availability import require_ros
from .drivers import UR_DASHBOARD_STOP

require_ros("a ROS stop service")

from std_srvs.srv import Trigger  # noqa: E402 - after the check that names what to install

__all__ = ["UR_DASHBOARD_STOP", "StopClient", "StopServer"]


class StopClient:
    """``call()`` -> the server's message; :class:`DeviceIOError` when no server answers within ``timeout_s``,
    :class:`DeviceError` when it answers ``success: false``."""

    def __init__(self, node: Any, service: str, *, timeout_s: float = 1.0) -> None:
        self.service, self.timeout_s = service, timeout_s
        self._client = node.create_client(Trigger, service)
        self._node = node

    def ready(self) -> bool:
        return bool(self._client.service_is_ready())

    def call(self) -> str:
        # discovery may still be under way (up to ~2 s): wait for the server within the call's time
        if not self.ready() and not self._client.wait_for_service(timeout_sec=self.timeout_s):
            raise DeviceIOError(f"no server of {self.service} (std_srvs/Trigger): is the arm's driver running, "
                                "on this ROS_DOMAIN_ID?")
        done = threading.Event()
        future = self._client.call_async(Trigger.Request())
        future.add_done_callback(lambda _: done.set())
        if not done.wait(self.timeout_s):
            future.cancel()
            raise DeviceIOError(f"{self.service}: no response within {self.timeout_s:g} s")
        response = future.result()
        if response is None or not response.success:
            why = "no response" if response is None else response.message or "success false"
            raise DeviceError(f"{self.service} refused the stop: {why}")
        return str(response.message)

    def close(self) -> None:
        self._node.destroy_client(self._client)


class StopServer:
    """Serves ``service``: each call runs ``stop()`` (its exception's message is the response's, with
    ``success: false``); ``calls`` and ``failures`` count them."""

    def __init__(self, node: Any, service: str, stop: Callable[[], None]) -> None:
        self.service, self._stop, self._node = service, stop, node
        self.calls = self.failures = 0
        self._server = node.create_service(Trigger, service, self._on_call)

    def _on_call(self, request: Any, response: Any) -> Any:
        self.calls += 1
        try:
            self._stop()
            response.success, response.message = True, "Stopped"  # the dashboard server's own reply
        except Exception as exc:  # noqa: BLE001 - the caller is told why, the publisher goes on
            self.failures += 1
            response.success, response.message = False, f"{type(exc).__name__}: {exc}"
        return response

    def close(self) -> None:
        self._node.destroy_service(self._server)
