"""The planned excitation played through the arm's own protocol (``ftc identify --plan`` on an arm that
takes goal positions, DYNAMIXEL, real or emulated), as ``ftc calibrate`` moves it: to the plan's start,
then its positions streamed as goals at 200 Hz while the live monitor pairs each F/T frame with the
joint state at its aligned time (what ``ftc monitor --record`` records); those pairs, with lost streams
cut out as from a recording, are the free motion the identification fits."""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from ftc_hw.bus import EVENTS_DEVICE
from ftc_hw.calibration.excitation import Excitation
from ftc_hw.calibration.free_motion import MotionData
from ftc_hw.monitor import MONITOR_INPUT, LiveMonitor
from ftc_hw.record.reader import RecordedMessage, Recording

from .device_session import DeviceSession

GOAL_HZ = 200.0  # goals a second: at 50 a second the servo's steps shake the arm well above the model's noise


def drive_excitation(session: DeviceSession, exc: Excitation, segments: Callable[..., tuple[list, dict]],
                     speed: float = 0.6,
                     progress: Callable[[float], None] | None = None) -> tuple[list[MotionData], dict[str, int]]:
    """``segments``: :func:`ftc_hw.app.calibration.identify.motion_segments` (what cuts a recording)."""
    session.torque_on()
    session.move_to(exc.reference(0.0)[0], speed=speed)
    inputs = session.bus.subscribe(MONITOR_INPUT, maxsize=None)
    events = session.bus.subscribe(EVENTS_DEVICE, maxsize=None)
    monitor = LiveMonitor(session.bus, session.scene, ft_source=session.ft_spec.name,
                          arm_source=session.arm_spec.name, tare_s=0.1)
    monitor.start()
    try:
        session.follow(lambda t: exc.reference(t)[0], exc.duration_s, rate_hz=GOAL_HZ, progress=progress)
    finally:
        monitor.stop()
    rec = Recording(Path("the driven excitation"), complete=True)
    rec.messages = sorted([RecordedMessage(MONITOR_INPUT, f.t_host_ns, f.t_host_ns, f) for f in inputs.drain()]
                          + [RecordedMessage(EVENTS_DEVICE, e.t_host_ns, e.t_host_ns, e) for e in events.drain()],
                          key=lambda m: m.log_time)
    # the untrained model's alarms are not contacts: nothing touches the arm while it plays the plan
    return segments(rec, keep_contacts=True)
