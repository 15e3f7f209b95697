"""A UR recording's data lines to arrays: rows that cannot be used are counted by reason and left
out, never used. Pure: lines in, :class:`Rows` out.

Reasons (``Rows.skipped`` keys), in the order a row is checked (it counts once, for the first it
fails): ``blank``, ``unterminated`` (the last line has no line end: the writer stopped inside it),
``cut_short`` / ``too_many_fields`` (fewer / more fields than the header), ``unparsable:<field>`` (a value
that is not a number), ``not_finite:<field>``, ``out_of_range:<field>`` (past :class:`PhysicalBounds`),
``time_jump`` (one row's ``timestamp`` ahead of the next row's while the rows around it are in order),
``time_repeated`` / ``time_backwards`` (a ``timestamp`` equal to / before the newest kept row's).
"""
from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from operator import itemgetter

import numpy as np

from .bounds import DEFAULT_BOUNDS, PhysicalBounds
from .header import Layout


@dataclass(frozen=True)
class Rows:
    """The kept rows: ``values[field]`` (m, k) for each field of the layout, ``line`` (m,) each row's
    1-based line in the file; ``total`` data lines (blank ones included); ``skipped`` by reason."""

    values: dict[str, np.ndarray]
    line: np.ndarray
    total: int
    skipped: Counter[str]


def _tokens(lines: Sequence[str], first_line: int, layout: Layout, terminated: bool,
            skipped: Counter[str]) -> tuple[list[str], list[int]]:
    """The used fields' tokens of the lines with the header's field count, flat (k a row), and each
    such line's number."""
    pick = itemgetter(*[c for cols in layout.fields.values() for c in cols])
    n_cols = len(layout.columns)
    out: list[str] = []
    numbers: list[int] = []
    for k, line in enumerate(lines):
        if not line.strip():
            skipped["blank"] += 1
            continue
        if k == len(lines) - 1 and not terminated:
            skipped["unterminated"] += 1
            continue
        parts = layout.split(line.strip())
        if len(parts) != n_cols:
            skipped["cut_short" if len(parts) < n_cols else "too_many_fields"] += 1
            continue
        out.extend(pick(parts))
        numbers.append(first_line + k)
    return out, numbers


def _floats(tokens: list[str], layout: Layout, skipped: Counter[str]) -> tuple[np.ndarray, np.ndarray]:
    """(m, k) floats of the rows that parse, and which rows those are (mask over the m rows)."""
    width = sum(len(c) for c in layout.fields.values())
    m = len(tokens) // width
    try:  # the common case: every token a number
        return np.fromiter(map(float, tokens), dtype=float, count=len(tokens)).reshape(m, width), np.ones(m, bool)
    except ValueError:
        pass
    out = np.zeros((m, width))
    ok = np.ones(m, dtype=bool)
    for i in range(m):
        row = tokens[i * width:(i + 1) * width]
        try:
            out[i] = [float(x) for x in row]
        except ValueError:
            ok[i] = False
            skipped[f"unparsable:{_first_bad(row, layout)}"] += 1
    return out, ok


def _first_bad(row: list[str], layout: Layout) -> str:
    at = 0
    for field, cols in layout.fields.items():
        for token in row[at:at + len(cols)]:
            try:
                float(token)
            except ValueError:
                return field
        at += len(cols)
    return "?"


def _check(values: dict[str, np.ndarray], keep: np.ndarray, bounds: PhysicalBounds,
           skipped: Counter[str]) -> None:
    """Clears ``keep`` where a field is not finite or out of bounds (counted by the first failing)."""
    for reason, test in (("not_finite", lambda f, v: np.isfinite(v).all(axis=1)),
                         ("out_of_range", bounds.within)):
        for field, v in values.items():
            bad = keep & ~test(field, v)
            if bad.any():
                skipped[f"{reason}:{field}"] += int(bad.sum())
                keep &= ~bad


def _spikes(t: np.ndarray) -> np.ndarray:
    """Single rows whose time is ahead of the next row's while the rows around them are in order (a
    corrupted timestamp): without them, every later row would count as going backwards."""
    out = np.zeros(len(t), dtype=bool)
    if len(t) >= 3:
        out[1:-1] = (t[1:-1] > t[2:]) & (t[:-2] < t[2:])
        out[0] = t[0] > t[1] and t[1] < t[2]
    return out


def in_time_order(t: np.ndarray, keep: np.ndarray, skipped: Counter[str]) -> None:
    """Keeps a row only if its time is after every earlier kept row's (the running maximum: a row not
    kept never raised it); a lone row ahead of its neighbours goes first (``time_jump``)."""
    idx = np.flatnonzero(keep)
    spike = _spikes(t[idx])
    skipped["time_jump"] += int(spike.sum())
    keep[idx[spike]] = False
    idx = idx[~spike]
    if idx.size < 2:
        return
    tk = t[idx]
    newest = np.maximum.accumulate(tk)[:-1]
    repeated = tk[1:] == newest
    backwards = tk[1:] < newest
    skipped["time_repeated"] += int(repeated.sum())
    skipped["time_backwards"] += int(backwards.sum())
    keep[idx[1:][repeated | backwards]] = False


def parse_rows(lines: Sequence[str], layout: Layout, *, first_line: int, terminated: bool = True,
               bounds: PhysicalBounds = DEFAULT_BOUNDS) -> Rows:
    """The usable rows of ``lines`` (data lines without their ends; ``first_line``: the file line of
    ``lines[0]``; ``terminated``: whether the file ends with a line end)."""
    skipped: Counter[str] = Counter()
    tokens, numbers = _tokens(lines, first_line, layout, terminated, skipped)
    flat, parsed = _floats(tokens, layout, skipped)
    values: dict[str, np.ndarray] = {}
    at = 0
    for field, cols in layout.fields.items():
        values[field] = flat[:, at:at + len(cols)]
        at += len(cols)
    keep = parsed.copy()
    _check(values, keep, bounds, skipped)
    in_time_order(values["timestamp"][:, 0], keep, skipped)
    kept = {f: np.ascontiguousarray(v[keep]) for f, v in values.items()}
    return Rows(kept, np.asarray(numbers, dtype=np.int64)[keep], len(lines), +skipped)
