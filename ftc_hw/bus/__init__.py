"""Timestamped bus: typed frames, publish/subscribe with history, statistics, watchdog, clock alignment.

Topics: ``wrench/<source>``, ``joints/<source>``, ``events/contact``, ``events/device`` (see
:mod:`ftc_hw.bus.bus`). Times are host ``time.monotonic_ns()`` unless named ``t_device_ns``.
"""

from .bus import EVENTS_CONTACT, EVENTS_DEVICE, Bus, StaleDataError, frame_topic, joints_topic, wrench_topic
from .clock import ClockAligner, ClockNotReadyError
from .frames import (
    CONTACT_CLASSES,
    CONTACT_KINDS,
    DEVICE_EVENT_KINDS,
    INTENTS,
    PROVISIONAL_EVENT_KINDS,
    STREAM_EVENT_KINDS,
    ContactEvent,
    ContactKind,
    DeviceEvent,
    DeviceEventKind,
    Frame,
    FrameError,
    JointFlag,
    JointFrame,
    LimitCheck,
    WrenchFlag,
    WrenchFrame,
)
from .history import SamplingPolicy, StateHistory
from .stats import StatsSnapshot, StreamStats
from .subscription import Empty, Subscription, SubscriptionClosed
from .watchdog import Watchdog

__all__ = [
    "CONTACT_CLASSES",
    "CONTACT_KINDS",
    "INTENTS",
    "DEVICE_EVENT_KINDS",
    "PROVISIONAL_EVENT_KINDS",
    "STREAM_EVENT_KINDS",
    "EVENTS_CONTACT",
    "EVENTS_DEVICE",
    "Bus",
    "ClockAligner",
    "ClockNotReadyError",
    "ContactEvent",
    "frame_topic",
    "ContactKind",
    "DeviceEvent",
    "DeviceEventKind",
    "Empty",
    "Frame",
    "FrameError",
    "JointFlag",
    "JointFrame",
    "LimitCheck",
    "SamplingPolicy",
    "StaleDataError",
    "StateHistory",
    "StatsSnapshot",
    "StreamStats",
    "Subscription",
    "SubscriptionClosed",
    "Watchdog",
    "WrenchFlag",
    "WrenchFrame",
    "joints_topic",
    "wrench_topic",
]
