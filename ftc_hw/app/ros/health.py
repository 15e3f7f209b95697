"""Stream health as ``diagnostic_msgs/DiagnosticStatus``: per stream the bus's own figures (``StreamStats``:
rate, count, sequence gaps, longest gap) fed with the frames the ROS view sees, the age of the newest, and
the state the monitor said (``sensor_lost`` / ``arm_lost`` until ``*_back``)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ftc_hw.bus import StreamStats

from . import encode as enc

STALE_S = 0.25  # no frame this long: STALE (the monitor's own loss threshold, ftc_hw.monitor.LOST_S)


@dataclass
class StreamHealth:
    """One stream: its name in the diagnostics, the device it comes from, its figures and its state."""

    name: str
    hardware_id: str
    stats: StreamStats = field(default_factory=StreamStats)
    lost: bool = False
    last_event: str = ""

    def update(self, t_host_ns: int, seq: int | None) -> None:
        self.stats.update(t_host_ns, seq)

    def status(self, now_ns: int, prefix: str) -> Any:
        s = self.stats.snapshot()
        age_s = None if s.last_t_host_ns is None else (now_ns - s.last_t_host_ns) / 1e9
        if self.lost:
            level, message = enc.ERROR, f"lost ({self.last_event})"
        elif age_s is None or age_s > STALE_S:
            level, message = enc.STALE, "no frame yet" if age_s is None else f"no frame for {age_s:.2f} s"
        elif s.seq_missing:
            level, message = enc.WARN, f"{s.seq_missing} frames missing (sequence gaps)"
        else:
            level, message = enc.OK, "ok"
        values = {"rate_hz": f"{s.rate_hz:.1f}", "age_s": "" if age_s is None else f"{age_s:.4f}",
                  "count": s.count, "seq_missing": s.seq_missing, "seq_backwards": s.seq_backwards,
                  "out_of_order": s.out_of_order, "max_gap_s": f"{s.max_gap_s:.4f}", "jitter_s": f"{s.jitter_s:.6f}",
                  "state": "lost" if self.lost else "ok" if level == enc.OK else message}
        return enc.diagnostic_status(level, f"{prefix}: {self.name}", message, self.hardware_id, values)


def counters_status(prefix: str, counters: dict[str, Any], published: dict[str, int]) -> Any:
    """The monitor's counters (frames judged, dropped, late, events, ...) and what the ROS side could not send."""
    failed = sum(v for k, v in published.items() if k.startswith("failed") or k.startswith("dropped"))
    level = enc.WARN if failed or counters.get("errors") else enc.OK
    message = f"{failed} messages not published" if failed else "ok"
    values = {**{k: v for k, v in sorted(counters.items())}, **{f"ros:{k}": v for k, v in sorted(published.items())}}
    return enc.diagnostic_status(level, f"{prefix}: monitor", message, "ftc", values)
