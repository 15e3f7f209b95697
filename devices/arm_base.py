"""What both arm adapters share: staleness they judge themselves (from their own device clock and
answers, not from a bus watchdog), marked on any reader failure and cleared by the next good sample."""
from __future__ import annotations

from collections.abc import Callable

from .base import Adapter, DeviceIOError


class ArmAdapter(Adapter):
    role = "arm"
    moves_on_goals = False  # set_goal (joint targets, rad) and set_torque move this arm
    _stale = False

    @property
    def stale(self) -> bool:
        """True between a ``stale`` event and the next good sample."""
        return self._stale

    def _mark_stale(self, why: str) -> None:
        if not self._stale:
            self._stale = True
            self.event("stale", why)

    def _mark_fresh(self, why: str) -> None:
        if self._stale:
            self._stale = False
            self.event("recovered", why)

    def _stale_on_failure(self, cycle: Callable[[], None]) -> None:
        """Run one reader cycle; a failure marks the stream stale before the base reports it and
        reconnects (either way no sample comes)."""
        try:
            cycle()
        except DeviceIOError as exc:
            self._mark_stale(f"link lost: {exc}")
            raise
        except Exception as exc:
            self._mark_stale(f"reader failed: {type(exc).__name__}: {exc}")
            raise
