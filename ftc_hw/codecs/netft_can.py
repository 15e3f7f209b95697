"""ATI Net F/T over CAN (the ur5e scene's sensor), described by a DBC file and decoded with cantools.

The DBC's frame IDs are relative to the DBC's request ID: the codec shifts them to the sensor's
``base_id`` (its DIP switches). One sample is four frames, base+1..base+3 (Fx,Tx / Fy,Ty / Fz,Tz)
and base+4 (status, sample counter), which closes it. :class:`NetFTAssembler` turns frames into
samples and never returns one with a missing, duplicated or malformed part.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cantools

from .errors import FrameFormatError
from .stream import StreamSample

BUILTIN_DIR = Path(__file__).resolve().parents[2] / "ftc_hw" / "scene" / "builtin"
OP_READ, OP_START, OP_STOP, OP_BIAS = 1, 2, 3, 4  # 4: init/bias, as a public driver sends it (issue 36)
STATUS_ERROR = 1 << 31
_DATA = ("NetFT_FxTx", "NetFT_FyTy", "NetFT_FzTz")
_PAIRS = (("Fx", "Tx"), ("Fy", "Ty"), ("Fz", "Tz"))


def resolve_dbc(dbc: str | Path) -> Path:
    """A DBC path, or the name of one shipped with the built-in scenes."""
    p = Path(dbc)
    if p.is_file():
        return p
    q = BUILTIN_DIR / p.name
    if q.is_file():
        return q
    raise FileNotFoundError(f"DBC file {dbc!r} not found (nor in {BUILTIN_DIR})")


@dataclass(frozen=True)
class CanPart:
    """One decoded frame: ``role`` is ``request`` (value: opcode), ``data`` (index 0..2, value: (f, t)),
    or ``status`` (value: (status, counter))."""

    role: str
    index: int
    value: tuple


class NetFTCodec:
    def __init__(self, dbc: str | Path = "ati_netft_can.dbc", base_id: int = 8) -> None:
        db = cantools.database.load_file(str(resolve_dbc(dbc)))
        self.request = db.get_message_by_name("NetFT_Request")
        self.data = tuple(db.get_message_by_name(n) for n in _DATA)
        self.status = db.get_message_by_name("NetFT_Status")
        self.base_id = base_id
        offset = base_id - self.request.frame_id
        self._roles = {self.request.frame_id + offset: ("request", 0, self.request)}
        for i, m in enumerate(self.data):
            self._roles[m.frame_id + offset] = ("data", i, m)
        self._roles[self.status.frame_id + offset] = ("status", 0, self.status)
        self.ids = tuple(sorted(self._roles))
        self._offset = offset

    def position(self, frame_id: int) -> int | None:
        """Place of a frame in a sample: 0..2 data, 3 status, -1 the request; None: not this sensor's."""
        role = self._roles.get(frame_id)
        if role is None:
            return None
        kind, index, _ = role
        return {"request": -1, "data": index, "status": 3}[kind]

    def frame_id(self, message) -> int:
        return message.frame_id + self._offset

    def encode_request(self, opcode: int) -> tuple[int, bytes]:
        return self.frame_id(self.request), self.request.encode({"Opcode": opcode})

    def encode_sample(self, wrench, counter: int, status: int = 0) -> list[tuple[int, bytes]]:
        """The four frames of one sample, in the order the sensor sends them."""
        out = []
        for i, m in enumerate(self.data):
            f, t = _PAIRS[i]
            out.append((self.frame_id(m), m.encode({f: round(float(wrench[i]), 3), t: round(float(wrench[3 + i]), 3)})))
        out.append((self.frame_id(self.status),
                    self.status.encode({"Status": status & 0xFFFFFFFF, "SampleCounter": counter & 0xFFFFFFFF})))
        return out

    def decode(self, frame_id: int, data: bytes) -> CanPart | None:
        """The part a frame carries; None for a frame that is not this sensor's. Raises
        :class:`FrameFormatError` for a frame of the sensor with the wrong length."""
        role = self._roles.get(frame_id)
        if role is None:
            return None
        kind, index, m = role
        if len(data) != m.length:
            raise FrameFormatError(f"{m.name}: {len(data)} data bytes, expected {m.length}", consumed=0)
        try:
            values = m.decode(bytes(data), decode_choices=False, scaling=True)
        except Exception as exc:  # noqa: BLE001 - cantools raises several types on bad data
            raise FrameFormatError(f"{m.name}: {exc}", consumed=0) from None
        if kind == "request":
            return CanPart(kind, 0, (int(values["Opcode"]),))
        if kind == "data":
            f, t = _PAIRS[index]
            return CanPart(kind, index, (float(values[f]), float(values[t])))
        return CanPart(kind, 0, (int(values["Status"]), int(values["SampleCounter"])))


class NetFTAssembler:
    """Frames in, whole samples out, never a sample mixed from two.

    Data frames carry no sample number, so a sample is only trusted when the counter proves which
    data frames are its own: the sensor sends data(n) then status(n), in ID order, so the frames
    received after status(c0) form runs (a frame whose position is not after the previous one starts
    a new run), each run from a later sample than the one before. With r runs before status(c), the
    last run is sample c exactly when c - c0 == r; otherwise whole samples were lost in between and
    the data cannot be attributed. The first sample after :meth:`reset` (no c0 yet) is therefore
    never published (``unverified``). Counters: ``incomplete`` (samples dropped for a missing,
    malformed or unattributable part), ``duplicates`` (repeated frames ignored), ``format_errors``
    (sensor frames of the wrong length), ``foreign`` (other IDs), ``unverified``.
    """

    def __init__(self, codec: NetFTCodec) -> None:
        self.codec = codec
        self._parts: list[tuple[float, float] | None] = [None, None, None]
        self._pos = -1  # position (0..2) of the newest data frame of the current run, -1: none
        self._spoiled = False  # the current run holds a malformed frame
        self._runs = 0  # data runs since the last status frame
        self._last_status: int | None = None
        self._answer = False  # the frames since the last request are one sample's answer
        self.incomplete = self.duplicates = self.format_errors = self.foreign = self.unverified = 0

    def expect_answer(self) -> None:
        """A request for one sample was just sent: what arrives next is that one sample (poll mode)."""
        if self._pos >= 0:
            self.incomplete += 1
        self._clear_run()
        self._runs = 0
        self._answer = True

    def reset(self) -> None:
        self._clear_run()
        self._runs = 0
        self._last_status = None

    def _clear_run(self) -> None:
        self._parts[:] = [None, None, None]
        self._pos = -1
        self._spoiled = False

    def counters(self) -> dict[str, int]:
        return {"incomplete": self.incomplete, "duplicates": self.duplicates, "format_errors": self.format_errors,
                "foreign": self.foreign, "unverified": self.unverified}

    def feed(self, frame_id: int, data: bytes) -> StreamSample | None:
        pos = self.codec.position(frame_id)
        if pos is None:
            self.foreign += 1
            return None
        if pos < 0:  # a request (another host on the bus)
            return None
        try:
            part = self.codec.decode(frame_id, data)
        except FrameFormatError:
            part = None
            self.format_errors += 1
        if pos == 3:
            return self._status(part)
        if part is not None and pos == self._pos and self._parts[pos] == part.value:
            self.duplicates += 1
            return None
        if pos <= self._pos or self._pos == -1:  # a new run
            if self._pos >= 0:
                self.incomplete += 1  # the previous run's sample lost its status frame
                self._clear_run()
            self._runs += 1
        self._pos = pos
        if part is None:
            self._spoiled = True
        else:
            self._parts[pos] = part.value
        return None

    def _status(self, part: CanPart | None) -> StreamSample | None:
        had_data = self._pos >= 0
        if part is None:  # a malformed status: its counter is unknown, so is the next sample's origin
            self.incomplete += had_data
            self._clear_run()
            self._runs = 0
            self._last_status = None
            return None
        status, counter = part.value
        if not had_data and self._runs == 0 and counter == self._last_status:
            self.duplicates += 1
            return None
        c0, runs, parts = self._last_status, self._runs, self._parts
        complete = not self._spoiled and all(p is not None for p in parts)
        self._last_status = counter
        self._runs = 0
        if self._answer:  # a polled sample: its frames came after the request, in one run
            self._answer = False
            c0 = counter - runs if runs == 1 else None
        if c0 is None:
            self.unverified += 1
            self._clear_run()
            return None
        if not complete or (counter - c0) % (1 << 32) != runs:
            self.incomplete += 1
            self._clear_run()
            return None
        w = tuple(p[0] for p in parts) + tuple(p[1] for p in parts)  # type: ignore[index]
        self._clear_run()
        return StreamSample(w, counter, None, status)
