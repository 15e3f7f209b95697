"""The recorder in a process of its own: :class:`RecorderProcess`, what ``ftc monitor --record`` runs.

In the monitor's process a thread drains the bus every ``poll_s`` and hands the batch over a pipe as
columns (:func:`pack`: a 7 kHz stream's frames and pipeline inputs cost about 2 us a sample to pack,
against 17 to encode as JSON and write as MCAP); the ``ftc-recorder`` process rebuilds the frames
(:func:`unpack`, the same values bit for bit, in the same order) and writes them with
:class:`~.writer.McapRecorder`, flushing every ``flush_s``. The encoding then no longer takes the
interpreter from the device readers and the pipeline (at 7 kHz it held it a third of the time).

Nothing is lost silently: a full bus queue drops its oldest frames (``drops``, as the in-process
recorder); a writer process that dies or cannot open the file is ``error`` (the frames not written
are counted in ``lost``), and the session reports both. A monitor that is killed leaves the writer to
finish the file from what reached it (a complete file, without the run's final metadata).

Other writers can run in the same process, on the same frames (``sinks``: the ROS 2 bag of
``ftc monitor --record-format ros2|both``, made by ``ftc_hw.app.ros``, which this layer does not import);
with ``ftc=False`` they are the only ones.
"""
from __future__ import annotations

import contextlib
import multiprocessing as mp
import pickle
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from ftc_hw.bus import Bus, WrenchFrame
from ftc_hw.monitor import JudgedFrame, PipelineInput
from ftc_hw.priority import name_process
from ftc_hw.scene import Scene

from .schemas import decode, encode, topic_of
from .writer import McapRecorder, end_polling

# the frequent frame types, sent as columns: their array fields stacked, the rest as lists
COLUMNS: dict[type, tuple[str, ...]] = {WrenchFrame: ("wrench",), PipelineInput: ("wrench", "q", "qd", "current"),
                                        JudgedFrame: ("external",)}
_CODE = {cls: i + 1 for i, cls in enumerate(COLUMNS)}  # 0: another kind, sent in its JSON
_FRAMES, _STOP = b"F", b"S"


def pack(frames: list[Any]) -> bytes:
    """A batch of bus frames as bytes for :func:`unpack` (which gives them back equal, in order; a frame
    of a type with no schema comes back as None, which the writer counts as skipped)."""
    try:
        return _pack(frames)
    except ValueError:  # arrays of another shape than their kind's others: every frame in its JSON
        return pickle.dumps((bytes(len(frames)), {}, [_json(f) for f in frames]), protocol=pickle.HIGHEST_PROTOCOL)


def _json(frame: Any) -> tuple[str, bytes] | None:
    try:
        return encode(frame)
    except TypeError:  # no schema for it
        return None


def _pack(frames: list[Any]) -> bytes:
    order = bytearray(len(frames))
    groups: dict[type, list[Any]] = {cls: [] for cls in COLUMNS}
    other: list[tuple[str, bytes] | None] = []  # the rare kinds (events, joint frames) in their JSON
    for i, f in enumerate(frames):
        group = groups.get(type(f))
        if group is None:
            other.append(_json(f))
        else:
            group.append(f)
            order[i] = _CODE[type(f)]
    columns = {}
    for cls, group in groups.items():
        if group:
            columns[_CODE[cls]] = _columns(cls, group)
    return pickle.dumps((bytes(order), columns, other), protocol=pickle.HIGHEST_PROTOCOL)


def _columns(cls: type, group: list[Any]) -> dict[str, Any]:
    stacked = COLUMNS[cls]
    out: dict[str, Any] = {}
    for f in fields(cls):
        values = [getattr(x, f.name) for x in group]
        out[f.name] = np.stack(values) if f.name in stacked else values
    return out


def unpack(data: bytes) -> list[Any]:
    order, columns, other = pickle.loads(data)
    rebuilt = {code: _rows(cls, columns[code]) for cls, code in _CODE.items() if code in columns}
    nexts = {code: iter(rows) for code, rows in rebuilt.items()}
    rest = (None if x is None else decode(*x) for x in other)
    return [next(rest) if code == 0 else next(nexts[code]) for code in order]


def _rows(cls: type, cols: dict[str, Any]) -> list[Any]:
    names = [f.name for f in fields(cls)]
    return [cls(*row) for row in zip(*(cols[n] for n in names), strict=True)]


@dataclass(frozen=True)
class Sink:
    """Another writer in the recorder's process: ``make(**kwargs)`` there (a module-level function: it reaches
    the process by its name) gives an object with ``write(frame)``, ``flush()`` and ``finish(final_metadata)
    -> dict`` (its summary: counts, errors). An exception in it is counted, never the ftc file's loss."""

    make: Callable[..., Any]
    kwargs: dict[str, Any] = field(default_factory=dict)


class RecorderProcess:
    """``McapRecorder``'s ``start`` / ``stop(final_metadata)`` / ``counts`` / ``drops`` / ``path``, with the
    writing in a process of its own (see the module doc); ``error`` says what went wrong, if anything."""

    def __init__(self, bus: Bus, path: Path | str, *, metadata: dict[str, dict[str, str]] | None = None,
                 prefix: str = "", scene: Scene | None = None, maxsize: int = 200_000, poll_s: float = 0.02,
                 flush_s: float = 0.2, start_timeout_s: float = 60.0, sinks: tuple[Sink, ...] = (),
                 ftc: bool = True) -> None:
        self.bus, self.path, self.prefix = bus, Path(path), prefix
        self.sinks, self.ftc = tuple(sinks), ftc
        self.metadata = dict(metadata or {})
        self.scene, self.maxsize, self.poll_s, self.flush_s = scene, maxsize, poll_s, flush_s
        self.start_timeout_s = start_timeout_s
        self.counts: Counter[str] = Counter()  # written, as the writer says at the end (else: handed over)
        self.drops = 0
        self.lost = 0  # frames handed to a writer that was gone
        self.error: str | None = None
        self.summary: dict[str, Any] = {}
        self._conn: Any = None
        self._proc: Any = None
        self._sub: Any = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()

    def start(self) -> RecorderProcess:
        if self._proc is not None:
            return self
        ctx = mp.get_context("spawn")
        here, there = ctx.Pipe()
        self._proc = ctx.Process(target=_writer_main, name="ftc-recorder", daemon=True,
                                 args=(there, str(self.path) if self.ftc else None, self.metadata, self.scene,
                                       self.flush_s, self.sinks))
        self._proc.start()
        there.close()
        self._conn = here
        if not here.poll(self.start_timeout_s):
            self._kill()
            raise OSError(f"recorder: the writer process did not start within {self.start_timeout_s:g} s")
        try:
            status = here.recv()
        except (EOFError, OSError):
            status = f"the writer process ended at its start (exit code {self._proc.exitcode})"
        if status != "ready":
            self._kill()
            raise OSError(f"recorder: {status}")
        self._sub = self.bus.subscribe(self.prefix, maxsize=self.maxsize, prefix=True)
        self._thread = threading.Thread(target=self._run, name="mcap-recorder", daemon=True)
        self._thread.start()
        return self

    def _kill(self) -> None:
        if self._proc is not None and self._proc.is_alive():
            self._proc.kill()
        if self._proc is not None:
            self._proc.join(5.0)

    def _hand_over(self, frames: list[Any]) -> None:
        if not frames:
            return
        if self.error is None:
            data = _FRAMES + pack(frames)
            try:
                self._conn.send_bytes(data)
                for f in frames:
                    self.counts[topic_of(f) or "?"] += 1
                return
            except (OSError, EOFError) as exc:  # the writer is gone
                self.error = f"the writer process is gone ({type(exc).__name__}: {exc})"
        self.lost += len(frames)

    def _run(self) -> None:
        # polls, as McapRecorder does: a waiting consumer would be woken by every publish
        while not self._sub.closed:
            self._send(self._sub.drain())
            self._stop.wait(self.poll_s)

    def _send(self, frames: list[Any]) -> None:
        try:
            self._hand_over(frames)
        except Exception as exc:  # noqa: BLE001 - said at the end, never a thread that dies unseen
            self.error = self.error or f"{type(exc).__name__}: {exc}"
            self.lost += len(frames)

    def stop(self, final_metadata: dict[str, dict[str, str]] | None = None) -> None:
        """Hand over what is queued and ``final_metadata``; wait for the writer to close the file."""
        if self._sub is None:
            return
        end_polling(self._sub, self._stop, self._thread)
        self._thread = None
        self._send(self._sub.drain())
        self.drops = self._sub.drops
        self._sub = None
        try:
            if self.error is None:
                self._conn.send_bytes(_STOP + pickle.dumps((self.drops, final_metadata or {})))
                if self._conn.poll(60.0):
                    self.summary = self._conn.recv()
                    self.counts = Counter(self.summary.get("counts", {}))
                else:
                    self.error = "the writer process did not finish the file within 60 s"
        except (OSError, EOFError) as exc:
            self.error = self.error or f"the writer process is gone ({type(exc).__name__}: {exc})"
        finally:
            self._conn.close()
            self._proc.join(10.0)
            self._kill()

    def __enter__(self) -> RecorderProcess:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


class _Sinks:
    """The sinks of the writer process, each fed apart: one that raises is counted and left, not the rest."""

    def __init__(self, specs: tuple[Sink, ...]) -> None:
        self.items = [spec.make(**spec.kwargs) for spec in specs]
        self.errors = [0] * len(self.items)
        self.first_error = [""] * len(self.items)

    def _guard(self, i: int, call: Callable[[], Any]) -> Any:
        try:
            return call()
        except Exception as exc:  # noqa: BLE001 - counted and said in the summary
            self.errors[i] += 1
            self.first_error[i] = self.first_error[i] or f"{type(exc).__name__}: {exc}"
            return None

    def write(self, frame: Any) -> None:
        for i, sink in enumerate(self.items):
            self._guard(i, lambda s=sink: s.write(frame))

    def flush(self) -> None:
        for i, sink in enumerate(self.items):
            self._guard(i, sink.flush)

    def finish(self, final: dict | None) -> list[dict[str, Any]]:
        out = []
        for i, sink in enumerate(self.items):
            summary = self._guard(i, lambda s=sink: s.finish(final)) or {}
            out.append({**summary, "errors": self.errors[i], "error": self.first_error[i]})
        return out


class _NoFile:
    """The ftc file's place when only sinks write (``ftc=False``)."""

    def __init__(self) -> None:
        self.counts: Counter[str] = Counter()
        self.skipped = self.drops = self.foxglove_errors = 0
        self.cpu_s = 0.0

    def write(self, frame: Any) -> None:
        self.counts["frames"] += 1

    def flush(self) -> None:
        pass

    def finish(self, final: Any) -> None:
        pass


def _open(conn: Any, path: str | None, metadata: dict, scene: Scene | None, flush_s: float,
          sinks: tuple[Sink, ...]) -> tuple[Any, _Sinks] | None:
    try:
        rec: Any = _NoFile()
        if path is not None:
            rec = McapRecorder(Bus(), path, metadata=metadata, scene=scene, flush_s=flush_s)
            rec.open()
        extra = _Sinks(sinks)
    except Exception as exc:  # noqa: BLE001 - said to the monitor, which raises it
        conn.send(f"cannot write {path or 'the recording'}: {type(exc).__name__}: {exc}")
        return None
    conn.send("ready")
    return rec, extra


def _writer_main(conn: Any, path: str | None, metadata: dict, scene: Scene | None, flush_s: float,
                 sinks: tuple[Sink, ...] = ()) -> None:
    """The writer process: frames from the pipe to the file (and the sinks) until stop (or the monitor's end
    of the pipe closes: then the file is finished from what came)."""
    name_process("ftc-recorder")
    opened = _open(conn, path, metadata, scene, flush_s, sinks)
    if opened is None:
        return
    rec, extra = opened
    drops, final = 0, None
    last_flush = time.monotonic()
    cpu0 = time.process_time()
    try:
        while True:
            if conn.poll(flush_s):
                data = conn.recv_bytes()
                if data[:1] == _STOP:
                    drops, final = pickle.loads(data[1:])
                    break
                for frame in unpack(data[1:]):
                    if frame is None:
                        rec.skipped += 1
                    else:
                        rec.write(frame)
                        extra.write(frame)
            if time.monotonic() - last_flush >= flush_s:
                rec.flush()
                extra.flush()
                last_flush = time.monotonic()
    except (EOFError, OSError):  # the monitor is gone: finish the file with what came
        pass
    rec.drops = drops
    rec.cpu_s = time.process_time() - cpu0
    rec.finish(final)
    sink_summaries = extra.finish(final)
    with contextlib.suppress(OSError, EOFError):  # the monitor is gone: nobody to tell
        conn.send({"counts": dict(rec.counts), "cpu_s": rec.cpu_s, "skipped": rec.skipped,
                   "foxglove_errors": rec.foxglove_errors, "sinks": sink_summaries})
