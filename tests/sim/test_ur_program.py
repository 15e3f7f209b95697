"""The emulated UR robot program that follows joint setpoints streamed over RTDE input registers
(sim_devices/ur_program.py, the register map in ftc_hw.codecs.ur_control_loop), stepped by hand on a fake
clock: the registers as the controller's input recipes set them, the flag's hand-over, the servo within
the scene's joint limits, the end of a stream, and the watchdog that pauses the program (UR's example arms
``rtde_set_watchdog(..., "PAUSE")``) when the client stops writing."""
from __future__ import annotations

import numpy as np
import pytest

from ftc_hw.codecs.ur_control_loop import CONTROL_LOOP, URAD, ControlLoopRegisters
from ftc_hw.sim_devices import ur_data as D
from ftc_hw.sim_devices.link import Command
from ftc_hw.sim_devices.ur import Controller
from ftc_hw.sim_devices.ur_program import ControlLoopProgram

pytestmark = pytest.mark.compute

DT = 0.002  # an e-Series controller cycle
VMAX, AMAX = 3.14, 20.0
Q0 = np.array([0.1, -1.5, 1.5, -1.5, -1.5, 0.2])


class FakeWorld:
    """The link's command side and the world's joint state, as the UR emulator sees them."""

    def __init__(self) -> None:
        self.sent: list[Command] = []
        self.q, self.qd = Q0.copy(), np.zeros(6)

    def send(self, cmd: Command) -> None:
        self.sent.append(cmd)


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture
def cell():
    world, clock = FakeWorld(), Clock()
    ctl = Controller((5, 9, 0, 0), world, "arm", "20205500001", "UR5")
    goals: list[tuple[np.ndarray, np.ndarray, float]] = []
    ctl.control_loop = ControlLoopProgram(
        n=6, period_s=DT, send_goal=lambda q, qd, h, t_rx: goals.append((q, qd, h)),
        joint_state=lambda: (world.q.copy(), world.qd.copy()), pause=ctl.watchdog_pause, max_speed=VMAX,
        max_acceleration=AMAX, clock=clock)
    return ctl, world, clock, goals


def _write(ctl: Controller, q, flag: int) -> None:
    """What ur_rtde's IO interface sends for one setpoint: each register its own input package, the flag last."""
    doubles, ints = CONTROL_LOOP.encode(q)
    for r, v in doubles.items():
        ctl.apply_input({f"input_double_register_{r}": v})
    for r, v in ints.items():
        ctl.apply_input({f"input_int_register_{r}": v})
    ctl.apply_input({CONTROL_LOOP.flag_name: flag})


def _run(ctl: Controller, clock: Clock, cycles: int) -> None:
    for _ in range(cycles):
        clock.t += DT
        ctl.control_loop.cycle()


def test_the_register_map_round_trips_and_refuses_what_it_cannot_carry():
    q = np.array([0.5, -1.2, 2.0, -3.0, 1.0, -6.2831])
    doubles, ints = CONTROL_LOOP.encode(q)
    assert sorted(doubles) == [18, 19, 20, 21, 22] and list(ints) == [19]
    assert ints[19] == round(-6.2831 / URAD)
    regs_d, regs_i = [0.0] * 48, [0] * 48
    for r, v in doubles.items():
        regs_d[r] = v
    for r, v in ints.items():
        regs_i[r] = v
    assert np.allclose(CONTROL_LOOP.decode(regs_d, regs_i), q, atol=URAD / 2)
    for bad in (q[:5], np.append(q[:5], np.nan), np.append(q[:5], 3000.0)):
        with pytest.raises(ValueError):
            CONTROL_LOOP.encode(bad)
    with pytest.raises(ValueError, match="watchdog"):
        ControlLoopProgram(n=6, period_s=DT, send_goal=print, joint_state=lambda: None, pause=print,
                           registers=ControlLoopRegisters(watchdog_hz=0.0))
    with pytest.raises(ValueError, match="joint registers"):
        ControlLoopProgram(n=5, period_s=DT, send_goal=print, joint_state=lambda: None, pause=print)


def test_the_flag_hands_over_the_joints_and_the_servo_keeps_to_the_limits(cell):
    ctl, world, clock, goals = cell
    target = Q0 + np.array([0.3, -0.2, 0.0, 0.0, 0.0, -0.1])
    doubles, _ = CONTROL_LOOP.encode(target)
    ctl.apply_input({f"input_double_register_{r}": v for r, v in doubles.items()})  # joints, no flag yet
    _run(ctl, clock, 10)
    assert not goals  # nothing handed over: the program is not following
    _write(ctl, target, 1)
    _run(ctl, clock, 400)
    q = np.array([g[0] for g in goals])
    v = np.array([g[1] for g in goals])
    assert np.allclose(q[-1], target, atol=1e-9) and np.allclose(v[-1], 0.0, atol=1e-9)
    assert np.all(np.abs(v) <= VMAX + 1e-9)
    assert np.all(np.abs(np.diff(np.vstack([np.zeros(6), v]), axis=0)) <= AMAX * DT + 1e-9)
    assert np.allclose(np.diff(q, axis=0), v[1:] * DT)  # each goal carries the velocity it moved at
    assert all(h == pytest.approx(2 * DT) for _, _, h in goals)
    # the slowest joint set the time: 0.3 rad at 20 rad/s^2 needs about 2 sqrt(0.3 / 20) = 0.245 s
    arrived = int(np.argmax(np.all(np.abs(q - target) < 1e-6, axis=1)))
    assert 0.24 <= (arrived + 1) * DT <= 0.3


def test_it_starts_from_the_arms_velocity_and_brakes(cell):
    """The arm was moving at 1 rad/s on joint 1 when the first setpoint (where it is) came: it brakes at
    the acceleration limit, overshoots by v^2 / 2a, and comes back."""
    ctl, world, clock, goals = cell
    world.qd = np.array([1.0, 0, 0, 0, 0, 0])
    _write(ctl, Q0, 1)
    _run(ctl, clock, 300)
    q = np.array([g[0] for g in goals])
    assert q[:, 0].max() - Q0[0] == pytest.approx(1.0 / (2 * AMAX), rel=0.15)
    assert q[-1, 0] == pytest.approx(Q0[0], abs=1e-9)


def test_flag_zero_finishes_the_move_then_stops_following(cell):
    ctl, world, clock, goals = cell
    target = Q0 + 0.2
    _write(ctl, target, 1)
    _run(ctl, clock, 5)
    ctl.apply_input({CONTROL_LOOP.flag_name: 0})
    _run(ctl, clock, 400)
    assert np.allclose(goals[-1][0], target, atol=1e-7)
    n = len(goals)
    _write_doubles_only = CONTROL_LOOP.encode(target + 0.5)[0]
    ctl.apply_input({f"input_double_register_{r}": v for r, v in _write_doubles_only.items()})
    clock.t += 5.0  # long after: no watchdog either (the stream had ended)
    _run(ctl, clock, 50)
    assert len(goals) == n and not ctl.control_loop.following
    assert ctl.runtime == D.RUNTIME_PLAYING and not world.sent


def test_the_watchdog_pauses_the_program_when_the_setpoints_stop(cell):
    """UR's example: rtde_set_watchdog("input_int_register_0", 1, "PAUSE"). Setpoints every cycle keep it
    quiet; none for longer than 1 / 1 Hz and the program pauses: the arm halts where it is (the world's
    stop command), the runtime state says PAUSED, and no more goals go out."""
    ctl, world, clock, goals = cell
    for k in range(100):  # 0.2 s of a stream
        _write(ctl, Q0 + 0.001 * k, k + 1)
        _run(ctl, clock, 1)
    assert ctl.runtime == D.RUNTIME_PLAYING and not world.sent
    _run(ctl, clock, int(0.99 / DT))  # the client went silent, just under a second
    assert ctl.runtime == D.RUNTIME_PLAYING and not world.sent
    _run(ctl, clock, 10)
    assert ctl.runtime == D.RUNTIME_PAUSED
    assert [c.kind for c in world.sent] == ["stop"]
    assert ctl.control_loop.counts["watchdog_pauses"] == 1
    n = len(goals)
    _run(ctl, clock, 50)
    assert len(goals) == n
    _write(ctl, Q0, 500)  # a paused program takes no setpoints until it plays again
    _run(ctl, clock, 5)
    assert len(goals) == n and ctl.control_loop.counts["not_playing"] == 1
    assert ctl.dashboard("play") == "Starting program"
    _write(ctl, Q0, 501)
    _run(ctl, clock, 5)
    assert len(goals) == n + 5


def test_a_setpoint_that_is_no_number_is_counted_not_followed(cell):
    ctl, world, clock, goals = cell
    ctl.apply_input({"input_double_register_18": float("nan"), CONTROL_LOOP.flag_name: 1})
    _run(ctl, clock, 5)
    assert not goals and ctl.control_loop.counts["bad_setpoints"] == 1
    # a dashboard stop ends the following, like a watchdog
    _write(ctl, Q0 + 0.1, 2)
    _run(ctl, clock, 5)
    assert ctl.dashboard("stop") == "Stopped"
    n = len(goals)
    _run(ctl, clock, 5)
    assert len(goals) == n
