"""Ground truth as JSON Lines: one line per sensor sample (SI units, base frame)."""
from __future__ import annotations

import json
from typing import IO

import numpy as np

from .world import WorldState


def truth_record(state: WorldState) -> dict:
    """``contact``, and for the strongest contact its ``link``, ``point`` (m) and ``force`` (N, on the arm).

    Every simultaneous contact is also listed under ``contacts``.
    """
    contacts = sorted(state.contacts, key=lambda c: -float(np.linalg.norm(c.force)))
    rec: dict = {"t": round(state.t, 9), "contact": bool(contacts)}
    if contacts:
        main = contacts[0]
        rec.update(link=main.link, point=_list(main.point), force=_list(main.force))
    else:
        rec.update(link=None, point=None, force=None)
    rec["contacts"] = [{"link": c.link, "point": _list(c.point), "force": _list(c.force), "source": c.source}
                       for c in contacts]
    rec["q"] = _list(state.q)
    return rec


def _list(v: np.ndarray) -> list[float]:
    return np.asarray(v, dtype=float).tolist()  # Python floats, as float(x) each


class TruthWriter:
    def __init__(self, stream: IO[str]) -> None:
        self.stream = stream
        self.lines = 0

    def write(self, state: WorldState) -> None:
        self.stream.write(json.dumps(truth_record(state), separators=(",", ":")) + "\n")
        self.lines += 1
