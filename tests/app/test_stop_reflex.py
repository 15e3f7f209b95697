"""The stop reflex acts on the first of a contact's provisional onset (a ``provisional_onset`` device event) and
its confirmed one, once (issue 40)."""
from __future__ import annotations

import numpy as np
import pytest

from ftc_hw.app.monitor.reflex import StopReflex
from ftc_hw.bus import EVENTS_CONTACT, EVENTS_DEVICE, Bus, ContactEvent, DeviceEvent

pytestmark = pytest.mark.compute

MS = 1_000_000


def _onset(t_ns: int) -> ContactEvent:
    return ContactEvent.make(t_ns, "onset", "wrist_3", np.zeros(3), np.zeros(3), contact_id=1)


def test_a_provisional_onset_stops_and_its_confirmation_does_not_stop_again():
    bus = Bus()
    sent: list[ContactEvent] = []
    reflex = StopReflex(bus, sent.append, inline=True)
    try:
        t0 = 10_000 * MS
        bus.publish(EVENTS_DEVICE, DeviceEvent.make(t0, "ft", "provisional_onset", "judged at once", {"d2": 90.0}))
        bus.publish(EVENTS_DEVICE, DeviceEvent.make(t0 + 1 * MS, "ft", "arm_lost", "not an onset"))
        bus.publish(EVENTS_CONTACT, _onset(t0 - 1 * MS))  # the confirmed onset, a frame earlier: the same contact
        bus.publish(EVENTS_CONTACT, _onset(t0 + 900 * MS))  # another contact: no provisional onset came
        bus.publish(EVENTS_DEVICE, DeviceEvent.make(t0 + 905 * MS, "ft", "provisional_onset", "late"))
    finally:
        reflex.close()
    assert [e.t_host_ns for e in sent] == [t0, t0 + 900 * MS]
    assert sent[0].flags == ("provisional",) and sent[1].flags == ()
    assert [s["provisional"] for s in reflex.stops] == [True, False]
    assert reflex.followed == 2
