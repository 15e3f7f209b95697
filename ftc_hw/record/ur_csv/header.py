"""The header line of a UR recording: which of the two formats it is, and where each field we use
sits. Pure: text in, a :class:`Layout` out (or :class:`URCsvError`).

Formats (docs/recording.md, "UR recordings in"):
- ``ur-client``: Universal Robots' RTDE client library, ``examples/record.py`` with ``rtde/csv_writer.py``:
  Python's ``csv.writer`` with ``delimiter=" "``, one header line, a vector field of size k (VECTOR6D,
  VECTOR3D, VECTOR6INT32 ...) as ``name_0`` .. ``name_<k-1>``, values as Python's ``str``.
- ``ur_rtde``: ur_rtde's ``RTDEReceiveInterface.startFileRecording(file, variables)``
  (``src/rtde_receive_interface.cpp``, ``include/ur_rtde/robot_state.h``): comma-separated, the same
  ``name_i`` header without a trailing comma, doubles as ``std::fixed`` with 6 decimals.
The format is told from the header's delimiter, never from the file's name.
"""
from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

from .errors import URCsvError

UR_CLIENT = "ur-client"
UR_RTDE = "ur_rtde"
FORMAT_NAMES = {UR_CLIENT: "UR RTDE client CSV (record.py, space-separated)",
                UR_RTDE: "ur_rtde file recording (comma-separated)"}

REQUIRED = ("actual_q", "actual_qd")
# the vector fields we read (VECTOR6D: six joints or a wrench), in the order rows are checked
OPTIONAL = ("actual_current", "target_current", "target_moment", "joint_temperatures", "ft_raw_wrench",
            "actual_TCP_force")

# the type names record.py --binary writes as its second line (rtde/csv_binary_writer.py)
_RTDE_TYPES = {"DOUBLE", "INT32", "UINT32", "UINT64", "UINT8", "BOOL", "INT64", "VECTOR6D", "VECTOR3D"}
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


@dataclass(frozen=True)
class Layout:
    """Where things are in a row. ``columns``: the header's names, in order; ``fields``: for each field
    we read (``timestamp`` and those of ``REQUIRED``/``OPTIONAL`` the file has), its column indices."""

    format: str  # UR_CLIENT | UR_RTDE
    columns: tuple[str, ...]
    fields: dict[str, tuple[int, ...]]

    def split(self, line: str) -> list[str]:
        """A data line's fields (the line without its end)."""
        return line.split(",") if self.format == UR_RTDE else line.split()


def _vector(name: str, index: dict[str, int]) -> tuple[int, ...] | None:
    """The columns ``name_0``, ``name_1``, ... (as many as there are, from 0); None when absent."""
    cols = []
    while f"{name}_{len(cols)}" in index:
        cols.append(index[f"{name}_{len(cols)}"])
    return tuple(cols) or None


def _tokens(line: str) -> tuple[str, list[str]]:
    text = line.strip()
    if "," in text:
        return UR_RTDE, [t.strip() for t in text.split(",")]
    return UR_CLIENT, text.split()


def _looks_numeric(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def parse_header(lines: Sequence[str], *, path: str) -> Layout:
    """The layout of a recording whose first lines are ``lines`` (the header, and the next line if
    any: RTDE's binary form has its types there). Raises :class:`URCsvError` naming ``path`` and the
    line on a file with no header, no ``timestamp`` or without ``actual_q`` / ``actual_qd``."""
    if not lines or not lines[0].strip():
        raise URCsvError(path, 1, "no header line (empty file or a blank first line)")
    fmt, names = _tokens(lines[0])
    if all(_looks_numeric(t) for t in names if t):
        raise URCsvError(path, 1, "no header: the first line holds numbers, not column names")
    bad = [t for t in names if not _NAME.match(t)]
    if bad:
        raise URCsvError(path, 1, f"not a header of RTDE field names: {bad[0]!r}")
    if len(lines) > 1 and lines[1].split() and set(lines[1].split()) <= _RTDE_TYPES:
        raise URCsvError(path, 2, "RTDE's binary recording (record.py --binary): record without --binary")
    index: dict[str, int] = {}
    for i, name in enumerate(names):
        if name in index:
            raise URCsvError(path, 1, f"column {name!r} twice")
        index[name] = i
    if "timestamp" not in index:
        raise URCsvError(path, 1, "no 'timestamp' column (the controller's time, s): cannot order the rows")
    fields: dict[str, tuple[int, ...]] = {"timestamp": (index["timestamp"],)}
    for name in REQUIRED + OPTIONAL:
        cols = _vector(name, index)
        if cols is None and name in REQUIRED:
            raise URCsvError(path, 1, f"no {name}_0 .. {name}_5 columns: record {', '.join(REQUIRED)}")
        if cols is not None:
            fields[name] = cols
    for name, cols in fields.items():
        if name != "timestamp" and len(cols) != 6:  # each a VECTOR6D: six joints, or a wrench
            raise URCsvError(path, 1, f"{name}: {len(cols)} columns {name}_0 .. {name}_{len(cols) - 1}, RTDE has 6")
    return Layout(fmt, tuple(names), fields)
