"""A UR recording's text to a :class:`URRecording`. Pure: the file's text in (its path only names it)."""
from __future__ import annotations

from pathlib import Path

from .bounds import DEFAULT_BOUNDS, PhysicalBounds
from .errors import URCsvError
from .header import parse_header
from .recording import URRecording
from .rows import parse_rows
from .timing import timing_of


def parse_ur_csv(text: str, *, path: Path | str, bounds: PhysicalBounds = DEFAULT_BOUNDS) -> URRecording:
    """The recording in ``text`` (either format, told from the header). :class:`URCsvError` when the
    file cannot be used at all: no header, no ``timestamp``, no ``actual_q``/``actual_qd``, fewer than
    two usable rows."""
    path = Path(path)
    text = text.removeprefix("\ufeff")  # a byte-order mark, as editors that saved the file may add
    lines = text.splitlines()
    layout = parse_header(lines[:2], path=str(path))
    rows = parse_rows(lines[1:], layout, first_line=2, terminated=text.endswith(("\n", "\r")), bounds=bounds)
    if len(rows.line) < 2:
        skipped = ", ".join(f"{n} {k}" for k, n in sorted(rows.skipped.items())) or "none"
        raise URCsvError(str(path), None, f"{len(rows.line)} usable rows of {rows.total} (skipped: {skipped}): "
                                          "a recording needs two or more")
    v = rows.values
    return URRecording(
        path=path, format=layout.format, columns=layout.columns, t=v["timestamp"][:, 0], q=v["actual_q"],
        qd=v["actual_qd"], current=v.get("actual_current"), ft_raw_wrench=v.get("ft_raw_wrench"),
        actual_tcp_force=v.get("actual_TCP_force"), target_current=v.get("target_current"),
        target_moment=v.get("target_moment"), joint_temperatures=v.get("joint_temperatures"),
        line=rows.line, rows=rows.total, skipped=rows.skipped, timing=timing_of(v["timestamp"][:, 0]))
