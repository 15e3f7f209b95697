"""The CPU a run's processes take, each apart, for ``ftc bench pipeline``'s real-time leg: this process (the
monitor: readers in threads, the pipeline) and every process it started (``ftc-world``, ``ftc-emu-<device>``,
``ftc-recorder``...: the names they give themselves, ``ftc_hw.priority.name_process``), and the whole host's
busy cores (what the other processes on it took), sampled every ``period_s`` from ``/proc`` in a thread.
Linux only: elsewhere only this process is sampled, from ``os.times``.
"""
from __future__ import annotations

import contextlib
import os
import threading
import time
from pathlib import Path

CLOCK_TICKS = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
SELF = "monitor"  # this process's name in the shares
HOST = "host (busy cores)"


def _stat(pid: int) -> tuple[str, int, float] | None:
    """(name, parent pid, CPU s) of a process from ``/proc/<pid>/stat``; None when it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    name, rest = text[text.index("(") + 1:text.rindex(")")], text[text.rindex(")") + 2:].split()
    return name, int(rest[1]), (int(rest[11]) + int(rest[12])) / CLOCK_TICKS  # state ppid ... utime stime


def descendants() -> dict[int, str]:
    """Every process started from this one, at any depth (a scan of ``/proc``): pid -> its name now."""
    stats: dict[int, tuple[str, int]] = {}
    for entry in os.scandir("/proc"):
        if entry.name.isdigit():
            st = _stat(int(entry.name))
            if st is not None:
                stats[int(entry.name)] = st[:2]
    ours, grew = {os.getpid()}, True
    while grew:
        new = {p for p, (_, pp) in stats.items() if pp in ours and p not in ours}
        ours |= new
        grew = bool(new)
    return {p: stats[p][0] for p in ours - {os.getpid()}}


def _host_busy_s() -> float | None:
    """The host's busy CPU seconds so far (every core: all but idle and iowait), from ``/proc/stat``."""
    try:
        fields = [int(x) for x in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    except (OSError, ValueError):
        return None
    return (sum(fields[:8]) - fields[3] - fields[4]) / CLOCK_TICKS  # user..steal less idle, iowait


class ProcessCpu:
    """CPU seconds per process of this run, sampled every ``period_s``: ``samples`` of (monotonic ns,
    {key: CPU s}), this process as ``SELF``, the host's busy seconds as ``HOST``, every process started from
    this one by its pid (named by :meth:`shares` with the name it gave itself last; found by a scan of
    ``/proc`` every ``scan_every`` samples); a process that ended keeps its last figure."""

    def __init__(self, period_s: float = 0.5, scan_every: int = 4) -> None:
        self.period_s = period_s
        self.scan_every = scan_every  # samples between two scans of /proc for new processes (tens of ms each)
        self.samples: list[tuple[int, dict[str | int, float]]] = []
        self.names: dict[int, str] = {}  # pid -> its newest name (a spawned process names itself after a while)
        self._last: dict[int, float] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="bench-cpu", daemon=True)

    def _children(self) -> None:
        """Find the processes started from this one since the last look."""
        for pid in descendants():
            self.names.setdefault(pid, "?")

    def _sample(self) -> None:
        t = os.times()
        now: dict[str | int, float] = {SELF: t.user + t.system}
        if os.path.isdir("/proc"):
            if len(self.samples) % self.scan_every == 0:
                with contextlib.suppress(OSError):
                    self._children()
            for pid in self.names:
                st = _stat(pid)
                if st is not None:
                    self.names[pid], self._last[pid] = st[0], st[2]
            busy = _host_busy_s()
            if busy is not None:
                now[HOST] = busy
        self.samples.append((time.monotonic_ns(), {**self._last, **now}))

    def _run(self) -> None:
        while not self._stop.is_set():
            self._sample()
            self._stop.wait(self.period_s)

    def __enter__(self) -> ProcessCpu:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()
        self._sample()

    def shares(self, t0_ns: int, t1_ns: int) -> dict[str, float]:
        """CPU seconds per wall second (1.0: one core) of each process between the first sample at or after
        ``t0_ns`` that has it (a process found later: from its first) and the last at or before ``t1_ns`` (host
        monotonic ns), by name (two of one name: with their pids); empty when fewer than two samples fall there."""
        inside = [s for s in self.samples if t0_ns <= s[0] <= t1_ns]
        if len(inside) < 2:
            return {}
        b_t, b = inside[-1]
        named = [self.names.get(k, "?") if isinstance(k, int) else k for k in b]
        out = {}
        for key, name in zip(b, named, strict=True):
            a_t, a = next(s for s in inside if key in s[1])
            if a_t < b_t:
                share = (b[key] - a[key]) / ((b_t - a_t) / 1e9)
                out[name if named.count(name) == 1 else f"{name}[{key}]"] = round(share, 3)
        return out
