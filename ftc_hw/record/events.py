"""Contact events as JSON Lines: ``{"t", "kind", "contact_id", "link", "point", "force", "point_std",
"flags", "probability", "duration_s", "peak_force", "impulse", "contact_class", "p_quasi_static", "intent",
"p_guidance", "class_features", "t_host_ns"}``.

``contact_id`` pairs a contact's onset, updates and offset. The offset carries the contact's last
estimate (link, point, force, point_std, as its last onset or update with an estimate said) and its
``duration_s`` (s), ``peak_force`` (N) and ``impulse`` (N s); a contact closed because a stream was
lost has an offset flagged ``lost``. Its class so far (final at the offset; docs/contacts.md):
``contact_class`` (``transient``, ``quasi_static``, ``unknown``) with ``p_quasi_static``, ``intent``
(``impact``, ``guidance``, ``unknown``) with ``p_guidance``, and the ``class_features`` it was drawn from.

The monitor's stream events go in the same file, in order: ``{"t", "kind", "source", "message",
"t_host_ns"}`` with ``kind`` one of ``sensor_lost``, ``sensor_back``, ``arm_lost``, ``arm_back``
(``source``: the device's name). A run whose file holds one was blind for a while.

An event judged against the cell's body limits (``ftc monitor --limits``, docs/limits.md) carries
``"limits": {"region", "region_from", "limit_kind", "class_assumed", "limit_n", "margin_n",
"effective_mass_kg", "speed_mps", "permissible_speed_mps"}`` (:class:`~ftc_hw.bus.LimitCheck`); a contact
whose force went past its limit has an event of kind ``exceedance`` (its figures as the event that
crossed, once per contact and limit kind).

``t`` is the event's time in seconds on the host's monotonic clock (``time.monotonic()``: the clock of
the MCAP log times and of the ground truth's ``t_host_ns``); ``t_host_ns`` gives it exactly, in ns.
``point`` (m), ``force`` (N, applied to the arm) and ``point_std`` (m, 1 sigma) are in the base frame.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import IO, Any

from ftc_hw.bus import ContactEvent, DeviceEvent, LimitCheck

LIMIT_FIELDS = ("region", "region_from", "limit_kind", "class_assumed", "limit_n", "margin_n", "effective_mass_kg",
                "speed_mps", "permissible_speed_mps")


def limit_record(c: LimitCheck) -> dict[str, Any]:
    return {k: getattr(c, k) for k in LIMIT_FIELDS}


def limit_check_of(d: dict[str, Any] | None) -> LimitCheck | None:
    """A record's ``limits`` (None: none); ValueError when it is not one."""
    if d is None:
        return None
    try:
        return LimitCheck(str(d["region"]), str(d["region_from"]), str(d["limit_kind"]), bool(d["class_assumed"]),
                          *(float(d[k]) for k in LIMIT_FIELDS[4:]))
    except (KeyError, TypeError) as exc:
        raise ValueError(f"limits: expected the fields {', '.join(LIMIT_FIELDS)} ({exc!r})") from None


def event_record(ev: ContactEvent | DeviceEvent) -> dict[str, Any]:
    if isinstance(ev, DeviceEvent):
        return {"t": ev.t_host_ns / 1e9, "kind": ev.kind, "source": ev.source, "message": ev.message,
                "t_host_ns": int(ev.t_host_ns)}
    out = {"t": ev.t_host_ns / 1e9, "kind": ev.kind, "contact_id": ev.contact_id, "link": ev.link,
           "point": [float(x) for x in ev.point], "force": [float(x) for x in ev.force],
           "point_std": [float(x) for x in ev.point_std], "flags": list(ev.flags),
           "probability": float(ev.probability), "duration_s": ev.duration_s, "peak_force": ev.peak_force,
           "impulse": ev.impulse, "contact_class": ev.contact_class, "p_quasi_static": ev.p_quasi_static,
           "intent": ev.intent, "p_guidance": ev.p_guidance, "class_features": dict(ev.class_features),
           "t_host_ns": int(ev.t_host_ns)}
    if ev.limits is not None:
        out["limits"] = limit_record(ev.limits)
    return out


def event_line(ev: ContactEvent | DeviceEvent) -> str:
    return json.dumps(event_record(ev), separators=(",", ":"))


class EventWriter:
    """Appends one line per event and flushes it (a killed monitor keeps every event written)."""

    def __init__(self, stream: IO[str]) -> None:
        self.stream = stream
        self.count = 0

    def write(self, ev: ContactEvent | DeviceEvent) -> None:
        self.stream.write(event_line(ev) + "\n")
        self.stream.flush()
        self.count += 1


def read_events(path: Path) -> list[dict[str, Any]]:
    with open(path, encoding="utf-8") as f:
        return [json.loads(line) for line in f if line.strip()]


def read_truth(path: Path) -> list[dict[str, Any]]:
    """Ground truth JSON Lines (``ftc monitor --sim --truth``): one record per sensor sample."""
    return read_events(path)
