"""Contact events as JSON Lines: ``{"t", "kind", "link", "point", "force", "point_std", "flags"}``.

``t`` is the event's time in seconds on the host's monotonic clock (``time.monotonic()``: the clock of
the MCAP log times and of the ground truth's ``t_host_ns``); ``t_host_ns`` gives it exactly, in ns.
``point`` (m), ``force`` (N, applied to the arm) and ``point_std`` (m, 1 sigma) are in the base frame.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import IO, Any

from ftc_hw.bus import ContactEvent


def event_record(ev: ContactEvent) -> dict[str, Any]:
    return {"t": ev.t_host_ns / 1e9, "kind": ev.kind, "link": ev.link, "point": [float(x) for x in ev.point],
            "force": [float(x) for x in ev.force], "point_std": [float(x) for x in ev.point_std],
            "flags": list(ev.flags), "probability": float(ev.probability), "t_host_ns": int(ev.t_host_ns)}


def event_line(ev: ContactEvent) -> str:
    return json.dumps(event_record(ev), separators=(",", ":"))


class EventWriter:
    """Appends one line per event and flushes it (a killed monitor keeps every event written)."""

    def __init__(self, stream: IO[str]) -> None:
        self.stream = stream
        self.count = 0

    def write(self, ev: ContactEvent) -> None:
        self.stream.write(event_line(ev) + "\n")
        self.stream.flush()
        self.count += 1


def read_events(path: Path) -> list[dict[str, Any]]:
    with open(path, encoding="utf-8") as f:
        return [json.loads(line) for line in f if line.strip()]


def read_truth(path: Path) -> list[dict[str, Any]]:
    """Ground truth JSON Lines (``ftc monitor --sim --truth``): one record per sensor sample."""
    return read_events(path)
