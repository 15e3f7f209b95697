"""The register map of the emulated UR robot program that takes joint setpoints over RTDE (no I/O here).

UR documents external control over RTDE input registers in its RTDE client library's example
(``examples/example_control_loop.py`` with the robot program ``rtde_control_loop.urp``): a thread of the
program copies six ``input_double_register``s (0-5) into a setpoint, ``input_int_register_0`` tells it a
new setpoint is there, and the program's ``BeforeStart`` arms ``rtde_set_watchdog("input_int_register_0",
1, "PAUSE")`` (URScript: no update of that input for longer than 1 / 1 Hz and the program pauses). Its
setpoint is a TCP pose moved to with MoveL; ours is the same program with joint angles (rad) tracked as a
servoj would, at registers ur_rtde's ``RTDEIOInterface`` can write. That client reaches only input
registers 18-22 (doubles and ints; 42-46 instead with ``use_upper_range_registers``: ur_rtde 1.6.5's
documentation of ``setInputDoubleRegister``), and a second interface for the upper range is refused (its
recipes name the same outputs: a controller answers IN_USE). So five joints take doubles 18-22, the
sixth an integer register in micro-radians (int 19: +-2147 rad, 1 urad is 0.85 um at a UR5e's reach),
and the flag is int 18.

The flag: each write of a value other than 0 hands the program the joint registers written before it as
its new target (the client writes the joints first, the flag last) and arms the watchdog; 0 ends the
stream (the arm stays where the last target took it; the watchdog disarmed).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

URAD = 1e-6  # rad per count of a joint in an integer register


@dataclass(frozen=True)
class ControlLoopRegisters:
    """Which RTDE input registers carry the joint targets (the scene's order: the doubles' joints first,
    then those in integer registers, in urad) and the flag; the watchdog's minimum update frequency."""

    q_doubles: tuple[int, ...] = (18, 19, 20, 21, 22)
    q_ints_urad: tuple[int, ...] = (19,)
    flag_int: int = 18
    watchdog_hz: float = 1.0  # UR's example: rtde_set_watchdog(..., 1, "PAUSE")

    @property
    def n_joints(self) -> int:
        return len(self.q_doubles) + len(self.q_ints_urad)

    @property
    def flag_name(self) -> str:
        return f"input_int_register_{self.flag_int}"

    def encode(self, q: Sequence[float]) -> tuple[dict[int, float], dict[int, int]]:
        """Joint angles (rad, shape (n_joints,)) as (double register -> value, int register -> urad).
        Raises ValueError for the wrong count, a value that is not finite or out of an int32's urad range."""
        q = np.asarray(q, dtype=float)
        if q.shape != (self.n_joints,) or not np.all(np.isfinite(q)):
            raise ValueError(f"expected {self.n_joints} finite joint angles (rad), got {q!r}")
        nd = len(self.q_doubles)
        ints = {r: round(float(v) / URAD) for r, v in zip(self.q_ints_urad, q[nd:], strict=True)}
        if any(not -(2**31) <= v < 2**31 for v in ints.values()):
            raise ValueError(f"joint angle beyond an int32 register's range in urad: {q[nd:]!r}")
        return dict(zip(self.q_doubles, (float(v) for v in q[:nd]), strict=True)), ints

    def decode(self, doubles: Sequence[float], ints: Sequence[int]) -> np.ndarray:
        """The joint angles (rad) in the registers (``doubles``, ``ints``: every input register, by number)."""
        return np.array([doubles[r] for r in self.q_doubles] + [ints[r] * URAD for r in self.q_ints_urad])


CONTROL_LOOP = ControlLoopRegisters()
