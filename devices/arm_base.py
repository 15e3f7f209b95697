"""What the arm adapters share: staleness they judge themselves (from their own device clock and
answers, not from a bus watchdog), marked on any reader failure and cleared by the next good sample;
the streamed joint setpoints of a reflex's motion (``servo``), where the arm's protocol takes them."""
from __future__ import annotations

from collections.abc import Callable, Sequence

from .base import Adapter, DeviceError, DeviceIOError


class ArmAdapter(Adapter):
    role = "arm"
    moves_on_goals = False  # set_goal (joint targets, rad) and set_torque move this arm
    _stale = False
    servo_period_s = 0.0  # how often servo() may be called (s); 0: this arm takes no streamed setpoints

    # -- streamed joint setpoints (the retreat reflex), for the arms whose protocol takes them --------------
    def prepare_servo(self) -> None:
        """Open what :meth:`servo` needs, before it is needed (a reflex must not wait for a handshake)."""
        raise DeviceError(f"{self.kind}: this arm takes no streamed joint setpoints")

    def servo(self, q: Sequence[float]) -> None:
        """The next joint setpoint of a stream (rad, the scene's joints), one every ``servo_period_s``."""
        raise DeviceError(f"{self.kind}: this arm takes no streamed joint setpoints")

    def end_servo(self) -> None:
        """The stream is over: the arm stays where its last setpoint took it."""
        raise DeviceError(f"{self.kind}: this arm takes no streamed joint setpoints")

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
