"""Writes a UR recording in either format, as the vendors' recorders do (for tests, and for users who
want a file the vendors' tools read): ``ur-client`` as UR's ``rtde/csv_writer.py`` (Python's
``csv.writer``, ``delimiter=" "``, its ``\\r\\n`` line ends, values as ``str``: repr, exact), ``ur_rtde`` as
``startFileRecording`` (commas, ``\\n``, doubles with 6 decimals, integers as they are)."""
from __future__ import annotations

import csv
import io
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from .header import UR_CLIENT, UR_RTDE


def _columns(columns: Mapping[str, np.ndarray]) -> tuple[list[str], list[np.ndarray]]:
    """The header's names (a field of k > 1 values as name_0 .. name_<k-1>) and each field as (m, k)."""
    names: list[str] = []
    blocks: list[np.ndarray] = []
    rows = None
    for name, values in columns.items():
        a = np.asarray(values)
        a = a.reshape(len(a), -1)
        if rows is not None and len(a) != rows:
            raise ValueError(f"{name}: {len(a)} rows, the others {rows}")
        rows = len(a)
        names += [f"{name}_{j}" for j in range(a.shape[1])] if a.shape[1] > 1 else [name]
        blocks.append(a)
    return names, blocks


def _rtde_value(x: float | int) -> str:
    return f"{x:.6f}" if isinstance(x, float) else str(x)


def ur_csv_text(columns: Mapping[str, np.ndarray], *, style: str = UR_CLIENT) -> str:
    """The file's text: ``columns`` maps each RTDE field name, in the file's order, to its values, (m,)
    or (m, k) (float arrays are doubles, integer arrays integers); ``style`` ``ur-client`` or ``ur_rtde``."""
    if style not in (UR_CLIENT, UR_RTDE):
        raise ValueError(f"style {style!r}: expected {UR_CLIENT!r} or {UR_RTDE!r}")
    names, blocks = _columns(columns)
    per_row = [b.tolist() for b in blocks]  # Python floats and ints: str() as csv.writer would
    rows = ([v for block in per_row for v in block[i]] for i in range(len(blocks[0]) if blocks else 0))
    if style == UR_RTDE:
        lines = [",".join(names)] + [",".join(_rtde_value(v) for v in row) for row in rows]
        return "\n".join(lines) + "\n"
    out = io.StringIO()
    writer = csv.writer(out, delimiter=" ")
    writer.writerow(names)
    writer.writerows(rows)
    return out.getvalue()


def write_ur_csv(path: Path | str, columns: Mapping[str, np.ndarray], *, style: str = UR_CLIENT) -> Path:
    """Writes :func:`ur_csv_text` to ``path`` (returned)."""
    path = Path(path)
    with open(path, "w", encoding="utf-8", newline="") as f:
        f.write(ur_csv_text(columns, style=style))
    return path
