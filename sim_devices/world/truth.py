"""Ground truth as JSON Lines: one line per sensor sample (SI units, base frame)."""
from __future__ import annotations

import json
from typing import IO

import numpy as np

from .world import ContactTruth, WorldState


def truth_record(state: WorldState) -> dict:
    """``contact``, and for the strongest contact its ``link``, ``point`` (m) and ``force`` (N, on the arm).

    Every simultaneous contact is also listed under ``contacts``; a scripted contact of a said kind carries it
    as ``class`` (``clamping``, ``guidance``, ``impact``: ``sim_devices/world/contact_kinds.py``).
    """
    contacts = sorted(state.contacts, key=lambda c: -float(np.linalg.norm(c.force)))
    rec: dict = {"t": round(state.t, 9), "contact": bool(contacts)}
    if contacts:
        main = contacts[0]
        rec.update(link=main.link, point=_list(main.point), force=_list(main.force))
    else:
        rec.update(link=None, point=None, force=None)
    rec["contacts"] = [{"link": c.link, "point": _list(c.point), "force": _list(c.force), "source": c.source}
                       | ({"class": c.label} if c.label else {}) for c in contacts]
    rec["q"] = _list(state.q)
    return rec


def _list(v: np.ndarray) -> list[float]:
    return np.asarray(v, dtype=float).tolist()  # Python floats, as float(x) each


_COMPACT = json.JSONEncoder(separators=(",", ":"))
_NAMES: dict[str, str] = {}  # link and source names as JSON strings


class _NotFinite(Exception):
    pass


def _name(s: str) -> str:
    out = _NAMES.get(s)
    if out is None:
        out = _NAMES[s] = json.dumps(s)
    return out


def _floats(v: np.ndarray) -> str:
    # a list's repr is its floats' reprs, what json writes for finite ones, joined by ", "
    out = repr(np.asarray(v, dtype=float).tolist())
    if "n" in out:  # nan or inf: json writes NaN, Infinity
        raise _NotFinite
    return out.replace(" ", "")


def _value(x: object) -> str:
    if type(x) is float:
        out = repr(x)
        if "n" in out:
            raise _NotFinite
        return out
    return str(x) if type(x) is int else json.dumps(x)


def _contact(c: ContactTruth) -> str:
    label = f',"class":{_name(c.label)}' if c.label else ""
    return (f'{{"link":{_name(c.link)},"point":{_floats(c.point)},"force":{_floats(c.force)},'
            f'"source":{_name(c.source)}{label}}}')


def truth_line(state: WorldState, fields: dict[str, object]) -> str:
    """The JSON line (with its newline) of ``truth_record(state)`` updated with ``fields``: byte for byte
    what ``json.dumps(..., separators=(",", ":"))`` writes, in about a third of its time (the world
    writes one per sensor sample, up to 7000 a second)."""
    try:
        return _fast_line(state, fields)
    except _NotFinite:
        rec = truth_record(state)
        rec.update(fields)
        return _COMPACT.encode(rec) + "\n"


def _fast_line(state: WorldState, fields: dict[str, object]) -> str:
    contacts = state.contacts
    if len(contacts) > 1:
        contacts = sorted(contacts, key=lambda c: -float(np.linalg.norm(c.force)))
    if contacts:
        c = contacts[0]
        head = f'"contact":true,"link":{_name(c.link)},"point":{_floats(c.point)},"force":{_floats(c.force)}'
    else:
        head = '"contact":false,"link":null,"point":null,"force":null'
    fields = dict(fields)
    t = _value(fields.pop("t", round(state.t, 9)))
    tail = "".join(f",{_name(k)}:{_value(v)}" for k, v in fields.items())
    return (f'{{"t":{t},{head},"contacts":[{",".join(_contact(c) for c in contacts)}],"q":{_floats(state.q)}'
            f'{tail}}}\n')


class TruthWriter:
    def __init__(self, stream: IO[str]) -> None:
        self.stream = stream
        self.lines = 0

    def write(self, state: WorldState) -> None:
        self.stream.write(truth_line(state, {}))
        self.lines += 1
