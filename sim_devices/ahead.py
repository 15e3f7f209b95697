"""A world's run computed ahead, then served on the wall clock (``ftc sim --world-ahead``, ``ftc monitor
--sim --world-ahead``): the simulated cell then costs only what its emulators' sockets cost.

The world's process first steps the world as fast as it goes (:func:`compute_run`, the same
:class:`~ftc_hw.sim_devices.runner.SimRunner` steps and readings as a live run: for a seed, the same
records), storing every joint sample and F/T reading (:mod:`ftc_hw.sim_devices.played`: ``.npy`` files in a
private directory, on ``/dev/shm`` where there is one) and the truth lines. Its phases are the live host's:

* pre-roll (with ``preroll``): ``PREROLL_S`` of the arm holding the scenario's start pose, nothing scripted;
  played as stored, then its last ``PREROLL_S - LOOP_FROM_S`` (the arm settled) over and over until ``go``
  (the lengths: :class:`AheadSpan`; at each seam a drifting sensor's bias steps back by its drift over the
  window, ur5e's 1-2 mN against its 0.3 N noise);
* the scenario, ``duration`` simulated seconds, its truth lines stored;
* post-roll: ``POSTROLL_S`` more (the scenario going on without truth); then the streams end and the
  devices fall silent (a monitor closes its adapters within 5 s of the scenario's end).

Then the emulators start and serve the stored run from it (:class:`AheadRunner`); the world's process only
waits on its pipe and on the emulators' commands, and writes the truth lines as they fall due (their
``t_host_ns`` and ``t_due_ns``: the time the sample was due; nothing publishes it, a record is there from
its time on).

What cannot be computed ahead: the arm's reaction to a command. A stop (a UR dashboard ``stop``, a
Dynamixel torque off), a goal, a retreat's setpoints are recorded as they arrive
(:meth:`WorldHost.applied`, with the emulator's own receive time ``t_rx_ns``: the command's arrival at the
arm's interface) and do nothing: **the played run goes on** as computed, the arm moving through the contact
as if nothing stopped it. The reflex's latency is therefore measured at the arm's interface (the stop
command's arrival in the emulator), not by the world's reaction; a test or run that needs the arm to obey
(calibration poses, a retreat's effect, ``--resume-after``'s halts in the truth) needs the live world.
"""
from __future__ import annotations

import dataclasses
import math
import os
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np

from .link import FT_WIDTH, Command, JointRecord
from .played import PlayControl, PlayedInfo, PlayedRing, StreamInfo, control_path, cut_at
from .runner import SimRunner
from .world import Hold
from .world.truth import truth_line

PREROLL_S = 3.0  # the stored pre-roll (ESTIMATE: the arm settles from its posed start within 0.5 s, SETTLE_S)
LOOP_FROM_S = 1.0  # from here on the pre-roll is played over and over until go (the arm still)
# after the scenario: a monitor waits up to 5 s for its backlog before it closes the adapters (a device that
# falls silent before is a dropped device in its summary)
POSTROLL_S = 6.0
GO_MARGIN_S = 0.02  # the scenario starts this far ahead of the clock when go comes (no record is read twice)
PROGRESS_EVERY_S = 1.0

Progress = Callable[[float, float], None]  # (simulated seconds computed, of how many)


@dataclass(frozen=True)
class AheadSpan:
    """How much is computed around the scenario (s): the pre-roll, where its loop window starts, the post-roll."""

    preroll_s: float = PREROLL_S
    loop_from_s: float = LOOP_FROM_S
    postroll_s: float = POSTROLL_S

    def __post_init__(self) -> None:
        if not 0.0 < self.loop_from_s < self.preroll_s or self.postroll_s < 0.0:
            raise AheadError(f"{self}: expected 0 < loop_from_s < preroll_s and postroll_s >= 0")


class AheadError(RuntimeError):
    """A run cannot be computed ahead as asked (no duration, not in real time) or was played wrong."""


class _Store:
    """Where the world's samples go while it is computed ahead (the link's ``publish_*``): rows
    ``[t, payload...]`` as the rings hold them, in arrays that grow by doubling."""

    def __init__(self, n_joints: int, ft: bool, steps: int, samples: int) -> None:
        self.joints = np.empty((max(steps, 16), 1 + JointRecord.width(n_joints)))
        self.ft = np.empty((max(samples, 16), 1 + FT_WIDTH)) if ft else None
        self.n_joints = self.n_ft = 0

    @staticmethod
    def _room(a: np.ndarray, n: int) -> np.ndarray:
        return a if n < len(a) else np.concatenate([a, np.empty_like(a)])

    def publish_ft(self, t: float, wrench: np.ndarray, saturated: np.ndarray) -> None:
        self.ft = self._room(self.ft, self.n_ft)
        row = self.ft[self.n_ft]
        row[0], row[1:7], row[7:13] = t, wrench, saturated  # bools stored as 0.0 / 1.0, as in the ring
        self.n_ft += 1

    def publish_joints(self, t: float, *parts: np.ndarray) -> None:
        """One :class:`JointRecord` (its fields in its order)."""
        self.joints = self._room(self.joints, self.n_joints)
        row = self.joints[self.n_joints]
        row[0] = t
        n = (len(row) - 1) // JointRecord.FIELDS
        for k, part in enumerate(parts):
            row[1 + k * n:1 + (k + 1) * n] = part
        self.n_joints += 1

    def mark(self) -> tuple[int, int]:
        """Rows stored so far: (joints, F/T)."""
        return self.n_joints, self.n_ft


class _Nowhere:
    """The samples of a world whose run was computed: nobody reads the rings."""

    def publish_ft(self, *args: Any) -> None:
        pass

    def publish_joints(self, *args: Any) -> None:
        pass


@dataclass(frozen=True)
class StoredRun:
    """A computed run: its streams (``info``), its truth lines (``{"t": scenario time, ...}`` without the
    host's fields) and each line's stored world time, its counts, and how long it took."""

    info: PlayedInfo
    truth_lines: Path
    truth_t: np.ndarray
    samples: int
    contact: int
    compute_s: float


def _sample_s(runner: SimRunner, seconds: float) -> float:
    """``seconds`` rounded to whole sample periods (the loop window and the cut keep the sample grid)."""
    rate = runner.world.sample_rate_hz
    return max(1, round(seconds * rate)) / rate


def compute_run(runner: SimRunner, directory: Path, *, preroll: bool, span: AheadSpan = AheadSpan(),
                progress: Progress | None = None) -> StoredRun:
    """Step ``runner``'s world through the pre-roll (``preroll``), its ``duration`` and the post-roll as
    fast as it goes (their lengths: ``span``), storing its samples and truth in ``directory``. The runner's
    emulators are not started."""
    t_start = time.monotonic()
    w = runner.world
    duration = runner.duration
    pre = ((_sample_s(runner, span.loop_from_s), _sample_s(runner, span.preroll_s - span.loop_from_s))
           if preroll else (0.0, 0.0))
    post = _sample_s(runner, span.postroll_s) if span.postroll_s > 0 else 0.0
    total = sum(pre) + duration + post
    store = _Store(runner.scene.n_joints, w.sensor is not None, math.ceil(total / w.dt) + 4,
                   math.ceil(total * w.sample_rate_hz) + 4)
    runner.out = store
    runner.publish_state()  # the state before the first step, as the live world publishes it first
    done = [0.0, time.monotonic()]  # simulated s computed before this phase, when progress was last said

    def phase(seconds: float, on_sample: Callable[[Any], None] | None = None) -> None:
        t0 = w.t

        def each(state: Any) -> None:
            if on_sample is not None:
                on_sample(state)
            if progress is not None and time.monotonic() - done[1] >= PROGRESS_EVERY_S:
                done[1] = time.monotonic()
                progress(done[0] + w.t - t0, total)

        runner.duration = seconds
        if seconds > 0:
            runner.run(realtime=False, on_sample=each)
        done[0] += seconds

    if preroll:  # as the live host's: the start pose held, nothing scripted, then the scenario from go
        w.set_reference(Hold(np.asarray(w.setup.trajectory.reference(0.0)[0], dtype=float)))
        w.hold_script()
        phase(pre[0])
        loop, t_loop = store.mark(), w.t
        phase(pre[1])
        scenario, t_go = store.mark(), w.t
        w.set_reference(w.setup.trajectory)
        w.start_script()
    else:  # the scenario from the first record on (its t = 0), as the live host's
        loop = scenario = (0, 0)
        t_loop = t_go = 0.0
    truth_path = directory / "truth.jsonl"
    truth_t: list[float] = []
    counts = [0, 0]
    with open(truth_path, "w", encoding="utf-8") as out:
        def truth(state: Any) -> None:
            truth_t.append(state.t)
            counts[0] += 1
            counts[1] += bool(state.contacts)
            out.write(truth_line(state, {"t": round(state.t - t_go, 9)}))

        phase(duration, truth)
    phase(post)
    runner.duration = duration
    info = _save(store, directory, loop, scenario, t_loop, t_go)
    return StoredRun(info, truth_path, np.array(truth_t), counts[0], counts[1], time.monotonic() - t_start)


def _save(store: _Store, directory: Path, loop: tuple[int, int], scenario: tuple[int, int], t_loop: float,
          t_go: float) -> PlayedInfo:
    np.save(directory / "joints.npy", store.joints[:store.n_joints])
    joints = StreamInfo(str(directory / "joints.npy"), loop[0], scenario[0])
    ft = None
    if store.ft is not None:
        np.save(directory / "ft.npy", store.ft[:store.n_ft])
        ft = StreamInfo(str(directory / "ft.npy"), loop[1], scenario[1])
    control = control_path(directory)
    PlayControl(control, create=True)
    return PlayedInfo(joints, ft, control, t_loop, t_go)


def store_directory() -> Path:
    """A private (0700) directory for a stored run: in memory (``/dev/shm``) where there is one."""
    shm = "/dev/shm"
    return Path(tempfile.mkdtemp(prefix="ftc-ahead-", dir=shm if os.path.isdir(shm) else None))


class AheadRunner(SimRunner):
    """A :class:`SimRunner` whose world is computed first (:meth:`compute`), then played to its emulators
    (:meth:`play`, :meth:`go`): they read the stored run (``link.info.played``), nothing steps. Commands
    are recorded (:attr:`applied`, at the played world time) and change nothing: the played run goes on."""

    def __init__(self, *args: Any, preroll: bool, span: AheadSpan = AheadSpan(), **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.preroll, self.span = preroll, span
        self.stored: StoredRun | None = None
        self.directory: Path | None = None
        self.control: PlayControl | None = None
        self.streams: dict[str, PlayedRing] = {}
        self.scenario_shift = 0.0  # s: played world time less stored, from the scenario's first record on

    def compute(self, progress: Progress | None = None) -> StoredRun:
        self.directory = store_directory()
        self.stored = compute_run(self, self.directory, preroll=self.preroll, span=self.span, progress=progress)
        info = self.stored.info
        self.link.info = dataclasses.replace(self.link.info, played=info)
        self.control = PlayControl(info.control, write=True)
        self.streams = {"joints": PlayedRing(info, ft=False, control=self.control)}
        if info.ft is not None:
            self.streams["ft"] = PlayedRing(info, ft=True, control=self.control)
        self.out = _Nowhere()
        return self.stored

    # -- the played clock ----------------------------------------------------------------------------------
    @property
    def _sample_stream(self) -> PlayedRing:
        """The stream on the sample grid: the F/T readings, else the joints (a scene without an F/T sensor)."""
        return self.streams.get("ft", self.streams["joints"])

    def play(self) -> float:
        """Start the played clock now; the played world time at which the scenario starts when there is no
        pre-roll (it starts at once), else None until :meth:`go`."""
        assert self.control is not None
        if not self.preroll:
            self.control.set_cut(0.0, 0, 0)
        self.control.start(time.monotonic_ns())
        return self.streams["joints"].t0

    def now(self) -> float:
        """The played world time (s)."""
        t = self.streams["joints"].now_s()
        return self.streams["joints"].t0 if t is None else t

    def go(self, margin_s: float = GO_MARGIN_S) -> float:
        """Cut the pre-roll's loop ``margin_s`` ahead of the clock, on the sample grid: the scenario's
        records from there. Returns the played world time of the scenario's t = 0. Raises AheadError when the
        clock passed the cut before it was set (this process held off the core that long: an emulator may
        have served the loop there)."""
        assert self.control is not None and self.stored is not None
        joints = self.streams["joints"]
        shift, k_joints, k_ft = cut_at(joints, self._sample_stream, self.now() + margin_s)
        self.control.set_cut(shift, k_joints, k_ft)
        self.scenario_shift = shift
        if self.now() >= float(joints.t[joints.b]) + shift:
            raise AheadError(f"go: the clock passed the cut ({margin_s * 1e3:g} ms ahead) before it was set")
        return self.stored.info.t_go + shift

    def due_ns(self, t: float) -> int | None:
        assert self.control is not None
        wall0 = self.control.wall0_ns
        return None if wall0 == 0.0 else round(wall0 + (t - self.streams["joints"].t0) * 1e9)

    def apply(self, cmd: Command) -> None:
        """Recorded at the played world time; the played run goes on (nothing can react to it)."""
        self.record(cmd, self.now())

    def stop(self) -> None:
        super().stop()
        if self.directory is not None:
            for f in self.directory.iterdir():
                f.unlink(missing_ok=True)
            self.directory.rmdir()
            self.directory = None


class TruthPlayer:
    """The stored truth lines written to ``out`` (None: only counted) as their samples fall due on the
    played clock, each with its played world time (``t_world``) and the host time it was due at
    (``t_host_ns`` and ``t_due_ns``)."""

    def __init__(self, runner: AheadRunner, out: IO[str] | None) -> None:
        assert runner.stored is not None
        self.runner, self.out = runner, out
        self.times = runner.stored.truth_t + runner.scenario_shift
        self.lines = open(runner.stored.truth_lines, encoding="utf-8")  # noqa: SIM115 - closed by close()
        self.next = 0

    @property
    def done(self) -> bool:
        return self.next >= len(self.times)

    def write_due(self) -> None:
        now = self.runner.now()
        for i in range(self.next, len(self.times)):
            t = float(self.times[i])
            if t > now:
                break
            line = self.lines.readline()
            if self.out is not None:
                due = self.runner.due_ns(t)
                self.out.write(f'{line[:-2]},"t_world":{round(t, 9)!r},"t_host_ns":{due},"t_due_ns":{due}}}\n')
            self.next = i + 1
        if self.out is not None:
            self.out.flush()

    def close(self) -> None:
        self.lines.close()
