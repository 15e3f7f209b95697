"""The real-time leg's cores kept apart: the simulated cell (``ftc-world``, ``ftc-emu-<device>``: the names
they give themselves, ``ftc_hw.priority.name_process``) on one core, the monitor (this process, every thread
of it, and the processes it started for itself: the recorder, reader processes) on the others. On a real cell
the monitor's host runs no simulated world; shared, the cell's processes (at a higher priority: they stand in
for controllers) take the cores the monitor's readers wait for, and the run measures the simulator.

Affinity is per thread on Linux; a thread or process inherits its creator's, so what this process starts runs on
the monitor's cores, and a process names itself a little after it starts: a thread re-pins every ``period_s``
what appeared since (a scan of ``/proc``: some milliseconds of this process's interpreter each). Linux only; a
host with one core cannot split (:func:`core_split` gives None).
"""
from __future__ import annotations

import contextlib
import os
import threading
from dataclasses import dataclass

from .process_cpu import descendants

CELL_PREFIXES = ("ftc-world", "ftc-emu-")


@dataclass(frozen=True)
class CoreSplit:
    cell: frozenset[int]  # the world and the emulators
    monitor: frozenset[int]  # this process and the rest of its children


def core_split() -> CoreSplit | None:
    """The lowest core of those this process may run on for the cell, the others for the monitor; None
    where affinity cannot be set or fewer than two cores are allowed."""
    if not hasattr(os, "sched_getaffinity"):
        return None
    cpus = sorted(os.sched_getaffinity(0))
    if len(cpus) < 2:
        return None
    return CoreSplit(frozenset(cpus[:1]), frozenset(cpus[1:]))


def _pin(pid: int, cpus: frozenset[int]) -> int:
    """Every thread of ``pid`` onto ``cpus``; how many were moved."""
    moved = 0
    with contextlib.suppress(OSError):
        for tid in os.listdir(f"/proc/{pid}/task"):
            with contextlib.suppress(OSError):
                if os.sched_getaffinity(int(tid)) != cpus:
                    os.sched_setaffinity(int(tid), cpus)
                    moved += 1
    return moved


class Pinned:
    """``with Pinned(split):`` the cell's processes on ``split.cell``, this process's threads and its other
    children on ``split.monitor``, until the block ends (then this process gets back its cores)."""

    def __init__(self, split: CoreSplit, period_s: float = 1.0) -> None:
        self.split, self.period_s = split, period_s
        self.moved = 0
        self._before = os.sched_getaffinity(0)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="bench-cores", daemon=True)

    def pin_now(self) -> None:
        self.moved += _pin(os.getpid(), self.split.monitor)
        for pid, name in descendants().items():
            self.moved += _pin(pid, self.split.cell if name.startswith(CELL_PREFIXES) else self.split.monitor)

    def _run(self) -> None:
        while not self._stop.is_set():
            self.pin_now()
            self._stop.wait(self.period_s)

    def __enter__(self) -> Pinned:
        self.pin_now()
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()
        _pin(os.getpid(), frozenset(self._before))
