"""CPU priority of the processes that stand in for, or talk to, real-time controllers.

The simulated world and the protocol emulators stand in for controllers that answer within their
cycle; the device readers and the stop reflex must get a command out within one. On a small shared
machine an ordinary process can wait a few milliseconds for a core, longer than a control period, so
these processes ask the OS to run them ahead of ordinary ones when it allows (root or CAP_SYS_NICE).
Without the privilege nothing changes; the benches report the tail either way. Beside it, how these
processes are named (:func:`name_process`) and ended (:func:`end_process`).
"""
from __future__ import annotations

import atexit
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager, suppress

# Nice values, all well short of the real-time classes; the world first (it stands in for the arm's
# controllers), then the emulators (device firmware), then the client side (readers and the reflex),
# so that no tier starves the one it waits on.
WORLD_NICE = -15
DEVICE_NICE = -10
READER_NICE = -5


def prefer_cpu(nice: int = DEVICE_NICE, *, exact: bool = False) -> bool:
    """Raise this process's priority to ``nice`` if allowed and not already higher; True if it is.
    ``exact``: also lower it to ``nice`` (a tier's own processes started by a higher tier). A process someone
    put in the background (a positive nice: ``nice -n 19``, as run-tests runs its computing tests) stays there:
    False, unchanged (a background job's world must not take the cores from a foreground one's)."""
    if not hasattr(os, "setpriority"):
        return False
    try:
        now = os.getpriority(os.PRIO_PROCESS, 0)
        if now <= nice and not exact:
            return True
        if now > 0:
            return False
        if now > nice or (exact and now != nice):
            os.setpriority(os.PRIO_PROCESS, 0, nice)
        return True
    except OSError:  # no privilege: run as an ordinary process
        return False


@contextmanager
def preferred_cpu(nice: int = DEVICE_NICE) -> Iterator[bool]:
    """``prefer_cpu`` for the duration of the block; the previous priority is restored after it
    (lowering a priority needs no privilege). Yields whether the raise took."""
    if not hasattr(os, "getpriority"):
        yield False
        return
    before = os.getpriority(os.PRIO_PROCESS, 0)
    raised = prefer_cpu(nice)
    try:
        yield raised
    finally:
        if raised and os.getpriority(os.PRIO_PROCESS, 0) != before:
            with suppress(OSError):
                os.setpriority(os.PRIO_PROCESS, 0, before)


def name_process(name: str) -> None:
    """Show this process as ``name`` (its first 15 bytes) in ps, top and /proc/<pid>/stat: the world, the
    emulators and the readers are all ``python -c spawn_main(...)`` to their command line."""
    with suppress(OSError), open("/proc/self/comm", "w", encoding="utf-8") as f:  # not Linux: stays python
        f.write(name[:15])


def end_process(code: int | str | None = 0) -> None:
    """Exit with ``code`` (``sys.exit``'s meaning) after the exit handlers and a flush of stdio, skipping
    Python's teardown of every module: unloading MuJoCo, numba, Zenoh and the rest took 0.15-0.45 s a process
    after its work was done (measured: the ``ftc`` command, the world's process, each emulator's), which a run,
    scripts and the test suite waited for. The caller has closed its files; the handlers end child processes
    and logging."""
    if isinstance(code, str):
        print(code, file=sys.stderr)
        code = 1
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:  # noqa: BLE001 - a closed pipe: nothing more to say
            code = code or 1
    os._exit(code or 0)
