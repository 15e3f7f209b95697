"""A world's run computed ahead and played on the wall clock (``ftc sim --world-ahead``): what an emulator
process reads instead of the world's rings.

The world's process computed the run first (:mod:`ftc_hw.sim_devices.ahead`) and stored each stream's
records, ``[t, payload...]`` as the rings hold them (:class:`~ftc_hw.sim_devices.link.JointRecord`, the
F/T ring's ``[t, wrench, saturated]``), in ``.npy`` files that every process maps (``np.load(mmap_mode="r")``:
one copy in the page cache). A :class:`PlayedRing` is a stream's ring as of now: record ``k`` is
there once the wall clock has reached its time, as the live world publishes a record when the host clock
reaches it (never ahead of it), and a :class:`~ftc_hw.sim_devices.link.RingReader` reads it as it reads
a ring. No process steps the world while it plays: the emulators wake on their own pace and take what is due.

The played timeline, in world seconds (``played``), is the stored one pieced together:

* before ``go``: the pre-roll as stored, then its window ``[t_loop, t_go)`` (the arm holding its start pose,
  settled) over and over, each repetition shifted by the window's length, until the scenario starts;
* from the cut (a sample time a margin ahead of the wall clock when ``go`` came, on the sample grid): the
  scenario's records, shifted so that the first lands on the cut, then the post-roll; after those the
  streams end (the devices fall silent).

A record's ``t`` is its played time (the stored one plus its piece's shift), so the emulators' sample
numbers and timestamps run on without a jump. The clock (``wall0``) and the cut live in a small shared
control file the world's process writes (:class:`PlayControl`); the emulators only read it.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

# control file: the wall clock's start (monotonic ns as a float; 0: not started), whether the cut is set,
# the scenario's shift (s), the cut's first index in the joint stream and in the F/T stream
_WALL0, _GO, _SHIFT, _CUT_JOINTS, _CUT_FT = range(5)
_CONTROL_WIDTH = 8
EPS_S = 1e-9  # a record exactly at the clock's time is due (float rounding of the sums of steps)


@dataclass(frozen=True)
class StreamInfo:
    """One stored stream: its file, and the rows where the pre-roll's loop window begins and ends (the
    scenario's first row is ``loop_end``: the window is the pre-roll's last part)."""

    path: str
    loop_start: int
    loop_end: int


@dataclass(frozen=True)
class PlayedInfo:
    """What a process needs to play a stored run (picklable): the streams, the control file, and the
    loop window's times (s, stored world time): ``t_loop`` its first record's, ``t_go`` the scenario's
    first record's (the window is ``[t_loop, t_go)``; equal when the run has no pre-roll)."""

    joints: StreamInfo
    ft: StreamInfo | None  # None: the scene has no F/T sensor
    control: str
    t_loop: float
    t_go: float


class PlayControl:
    """The shared control file: written by the world's process (``create``), read by every other."""

    def __init__(self, path: str, create: bool = False, write: bool = False) -> None:
        """``create``: a new file (all zero: not started); ``write``: this process writes it."""
        if create:
            np.zeros(_CONTROL_WIDTH).tofile(path)
        # a plain array on the map (a memmap's indexing costs more; the map lives as its base)
        self.values = np.asarray(np.memmap(path, dtype=np.float64, mode="r+" if create or write else "r",
                                           shape=(_CONTROL_WIDTH,)))

    @property
    def wall0_ns(self) -> float:
        return float(self.values[_WALL0])

    def start(self, wall0_ns: int) -> None:
        """Played time starts now: the first record's time is due at ``wall0_ns`` (monotonic ns)."""
        self.values[_WALL0] = float(wall0_ns)

    def set_cut(self, shift_s: float, cut_joints: int, cut_ft: int) -> None:
        """The scenario from these indices on, shifted by ``shift_s``; the flag written last (a reader that
        sees it sees the rest)."""
        v = self.values
        v[_SHIFT], v[_CUT_JOINTS], v[_CUT_FT] = shift_s, float(cut_joints), float(cut_ft)
        v[_GO] = 1.0

    def cut(self, ft: bool) -> tuple[int, float] | None:
        """(the stream's first index of the scenario, its shift in s), or None before ``go``."""
        v = self.values
        if v[_GO] == 0.0:
            return None
        return int(v[_CUT_FT if ft else _CUT_JOINTS]), float(v[_SHIFT])


class PlayedRing:
    """A stored stream as a ring of records due by now (the interface :class:`RingReader` reads:
    ``written``, ``read(k)``, ``slots``). Record 0 (the world's state before its first step, which the
    live world publishes before its emulators start) is there from the start; the others from their
    played time on, once the clock has started."""

    slots = 1 << 62  # nothing is ever overwritten: a reader never falls a ring behind

    def __init__(self, info: PlayedInfo, ft: bool, control: PlayControl | None = None) -> None:
        stream = info.ft if ft else info.joints
        if stream is None:
            raise LookupError("the stored run has no F/T stream (its scene has no [sensor])")
        self.ft = ft
        self.data = np.asarray(np.load(stream.path, mmap_mode="r"))  # rows read from the map as they are due
        self.t = np.ascontiguousarray(self.data[:, 0])  # searched at every look: a copy of its own
        self.width = self.data.shape[1] - 1
        self.a, self.b = stream.loop_start, stream.loop_end
        self.t_loop, self.t_go = info.t_loop, info.t_go
        self.period = info.t_go - info.t_loop  # the loop window's length (s); 0: no pre-roll, nothing loops
        self.t0 = float(self.t[0])
        self.control = control or PlayControl(info.control)

    def now_s(self) -> float | None:
        """Played world time now (s), None before the clock started."""
        wall0 = self.control.wall0_ns
        if wall0 == 0.0:
            return None
        return self.t0 + (time.monotonic_ns() - wall0) / 1e9

    @property
    def written(self) -> int:
        now = self.now_s()
        return 1 if now is None else max(1, self.count(now))

    def count(self, played: float) -> int:
        """How many records have a played time at or before ``played`` (s)."""
        cut = self.control.cut(self.ft)
        if cut is not None and played >= self.played_time(cut[0], cut):
            k, shift = cut
            rest = int(np.searchsorted(self.t[self.b:], played - shift + EPS_S, side="right"))
            return k + rest
        return self.count_before_go(played)

    def count_before_go(self, played: float) -> int:
        """The count on the timeline without a cut: the pre-roll, then its window repeated."""
        if played < self.t_go or self.period <= 0.0:
            return int(np.searchsorted(self.t[:self.b], played + EPS_S, side="right"))
        reps = math.floor((played - self.t_go) / self.period)
        within = self.t_loop + (played - self.t_go - reps * self.period)
        return self.b + reps * (self.b - self.a) + int(np.searchsorted(self.t[self.a:self.b], within + EPS_S,
                                                                           side="right"))

    def source(self, k: int, cut: tuple[int, float] | None) -> tuple[int, float]:
        """(the stored row, the shift in s) of played record ``k``."""
        if cut is not None and k >= cut[0]:
            return self.b + (k - cut[0]), cut[1]
        if k < self.b or self.b == self.a:
            return k, 0.0
        reps, r = divmod(k - self.b, self.b - self.a)
        return self.a + r, (reps + 1) * self.period

    def played_time(self, k: int, cut: tuple[int, float] | None) -> float:
        row, shift = self.source(k, cut)
        return float(self.t[row]) + shift if row < len(self.t) else math.inf

    def read(self, k: int) -> np.ndarray | None:
        """Record ``k`` (``[t, payload...]``, its played time), None past the stored run's end."""
        row, shift = self.source(k, self.control.cut(self.ft))
        if row >= len(self.t):
            return None
        out = np.array(self.data[row])
        out[0] += shift
        return out

    @property
    def stored(self) -> int:
        return len(self.t)

    def close(self) -> None:
        """Nothing to release (the maps go with the arrays)."""


def cut_at(joints: PlayedRing, sample: PlayedRing, played_s: float) -> tuple[float, int, int]:
    """Where the scenario starts when ``go`` comes at played time ``played_s`` (a margin ahead of the clock):
    at the first record of ``sample`` (the stream on the sample grid: the F/T readings, else ``joints``)
    after it, which the scenario's first sample record replaces; the joint stream cut at the same shift,
    so that every record keeps its partner of the same stored time and both grids run on without a gap.
    Returns (the shift in s, the joint stream's first scenario index, the sample stream's)."""
    k = sample.count_before_go(played_s)
    shift = sample.played_time(k, None) - float(sample.t[sample.b])
    step = float(joints.t[1] - joints.t[0]) if joints.stored > 1 else 0.0
    k_joints = joints.count_before_go(float(joints.t[joints.b]) + shift - step / 2)
    return shift, k_joints, k if sample is not joints else k_joints


def control_path(directory: str | Path) -> str:
    return str(Path(directory) / "control.f64")
