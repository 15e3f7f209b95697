"""The emulated UR controller's robot program that follows joint setpoints streamed over RTDE input registers.

The controller's side of UR's documented external-control example (``rtde_control_loop.urp`` of UR's RTDE
client library), with joint targets and the registers of ``ftc_hw.codecs.ur_control_loop``: each write of
the flag register (non-zero) hands the program the joint registers as its target and (re)arms the watchdog;
0 ends the stream: the servo goes on to the last target (it may lag the stream) and stays there. The
watchdog is URScript's ``rtde_set_watchdog(flag, watchdog_hz, "PAUSE")``: no write of the flag for longer
than 1 / watchdog_hz while streaming and the program pauses (runtime PAUSED, the arm halts where it is).

Servo (what a ``servoj`` does each controller cycle, 2 ms on an e-Series, 8 ms on a CB3): UR documents
servoj's ``lookahead_time`` and ``gain`` but not its control law (URScript manual: "a" and "v" unused).
ESTIMATE: the command moves toward the target as fast as the scene's joint speed and acceleration limits
(``[robot] max_speed``, ``max_acceleration``) allow -- the velocity that would still stop on the target,
``sqrt(2 a |e|)``, never more than the remaining error per cycle -- starting from the arm's own velocity (it
brakes first when it was moving the other way); no lookahead smoothing (the client streams a time-
parametrised path). Each cycle's command goes to the world as a goal with its velocity (``Command("goal", q,
extra={"qd", "horizon_s"})``): the world's joint controller gets the feed-forward a servo loop has. Where
the scene has no limits, UR5e's datasheet speed (3.14 rad/s) and ur_rtde's acceleration bound for movej (40
rad/s^2).
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from ftc_hw.codecs.ur_control_loop import CONTROL_LOOP, ControlLoopRegisters

DEFAULT_MAX_SPEED = 3.14  # rad/s, UR5e datasheet (every joint 180 deg/s)
DEFAULT_MAX_ACCELERATION = 40.0  # rad/s^2, ur_rtde's UR_JOINT_ACCELERATION_MAX


class ControlLoopProgram:
    """The program's state. ``send_goal(q, qd, horizon_s, t_rx_ns)`` moves the world; ``joint_state()`` is the
    world's newest (q, qd) or None; ``pause()`` is the controller's watchdog action."""

    def __init__(self, *, n: int, period_s: float, send_goal: Callable[..., None],
                 joint_state: Callable[[], tuple[np.ndarray, np.ndarray] | None], pause: Callable[[], None],
                 max_speed: Any = None, max_acceleration: Any = None,
                 registers: ControlLoopRegisters = CONTROL_LOOP, clock: Callable[[], float] = time.monotonic) -> None:
        if registers.n_joints != n:
            raise ValueError(f"{registers.n_joints} joint registers for {n} joints")
        if not registers.watchdog_hz > 0.0:
            raise ValueError(f"watchdog_hz {registers.watchdog_hz!r}: expected a frequency > 0")
        self.n, self.period_s, self.registers = n, float(period_s), registers
        self.vmax = np.broadcast_to(np.asarray(DEFAULT_MAX_SPEED if max_speed is None else max_speed, float), (n,))
        self.amax = np.broadcast_to(np.asarray(DEFAULT_MAX_ACCELERATION if max_acceleration is None
                                               else max_acceleration, float), (n,))
        self._send_goal, self._joint_state, self._pause, self._clock = send_goal, joint_state, pause, clock
        self.following = False
        self.ending = False  # flag 0 came: on to the last target, then done
        self.target: np.ndarray | None = None
        self.q_cmd: np.ndarray | None = None
        self.v_cmd = np.zeros(n)
        self.last_flag_s = 0.0
        self.t_rx_ns = 0
        self.counts = {"setpoints": 0, "bad_setpoints": 0, "watchdog_pauses": 0, "goals": 0, "not_playing": 0}
        self.wake = threading.Event()
        self._lock = threading.Lock()  # register writes (RTDE sessions' threads) against the cycle's thread

    # -- register writes (under the controller's lock) ---------------------------------------------------------
    def on_flag(self, flag: int, doubles: list[float], ints: list[int], t_rx_ns: int = 0) -> None:
        """The flag register was written (``doubles``, ``ints``: every input register, by number)."""
        with self._lock:
            if flag == 0:
                self.ending = self.following
                return
            q = self.registers.decode(doubles, ints)
            if not np.all(np.isfinite(q)):
                self.counts["bad_setpoints"] += 1
                return
            if not self.following:  # the servo starts where the arm is, at the arm's velocity
                state = self._joint_state()
                if state is None:
                    self.counts["bad_setpoints"] += 1
                    return
                self.q_cmd, self.v_cmd = np.array(state[0], float), np.array(state[1], float)
            self.target, self.following, self.ending, self.t_rx_ns = q, True, False, t_rx_ns
            self.last_flag_s = self._clock()
            self.counts["setpoints"] += 1
        self.wake.set()

    def halt(self) -> None:
        """The program stopped or paused (dashboard, watchdog): no more following."""
        with self._lock:
            self.following = False

    # -- the controller's cycle ----------------------------------------------------------------------------------
    def cycle(self) -> None:
        """One controller period: the watchdog, then one servo step toward the target, sent to the world."""
        with self._lock:
            if not self.following or self.target is None or self.q_cmd is None:
                return
            starved = not self.ending and self._clock() - self.last_flag_s > 1.0 / self.registers.watchdog_hz
            if starved:
                self.following = False
                self.counts["watchdog_pauses"] += 1
            else:
                self.q_cmd, self.v_cmd = servo_step(self.q_cmd, self.v_cmd, self.target, self.period_s, self.vmax,
                                                    self.amax)
                q, v, t_rx_ns = self.q_cmd.copy(), self.v_cmd.copy(), self.t_rx_ns
                if self.ending and np.all(np.abs(self.target - q) < 1e-7) and np.all(np.abs(v) < 1e-4):
                    self.following = self.ending = False  # arrived: the stream is over
        if starved:
            self._pause()  # outside the lock: the controller's halt calls halt() here
            return
        self._send_goal(q, v, 2.0 * self.period_s, t_rx_ns)
        self.counts["goals"] += 1

    def run(self, stop: threading.Event) -> None:
        """The program's thread: a cycle every period while following (absolute deadlines), asleep otherwise."""
        next_t = time.monotonic()
        while not stop.is_set():
            if not self.following:
                self.wake.wait(0.1)
                self.wake.clear()
                next_t = time.monotonic()
                continue
            self.cycle()
            next_t += self.period_s
            delay = next_t - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            else:
                next_t = time.monotonic()  # late (a loaded host): no burst of catch-up cycles


def servo_step(q: np.ndarray, v: np.ndarray, target: np.ndarray, dt: float, vmax: np.ndarray,
               amax: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One cycle toward ``target`` (rad) from (q rad, v rad/s): the velocity that still stops on the target
    (``sqrt(2 a |e|)``, at most the error per cycle and ``vmax``), reached within ``amax dt`` of ``v``."""
    e = target - q
    stop_speed = np.sqrt(2.0 * amax * np.abs(e))
    want = np.sign(e) * np.minimum(np.minimum(stop_speed, np.abs(e) / dt), vmax)
    v_new = v + np.clip(want - v, -amax * dt, amax * dt)
    return q + v_new * dt, v_new


