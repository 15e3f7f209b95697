"""UR recordings from files: one, or several at once (identification takes several)."""
from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from .bounds import DEFAULT_BOUNDS, PhysicalBounds
from .errors import URCsvError
from .parse import parse_ur_csv
from .recording import URRecording


def read_ur_csv(path: Path | str, *, bounds: PhysicalBounds = DEFAULT_BOUNDS) -> URRecording:
    """The recording in the file at ``path`` (UR's RTDE client CSV or ur_rtde's file recording, told
    from its content). Raises :class:`URCsvError` naming the file (and line) when it cannot be used."""
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as exc:
        raise URCsvError(str(path), None, f"cannot read: {exc.strerror or exc}") from None
    return parse_ur_csv(data.decode("utf-8", errors="replace"), path=path, bounds=bounds)


def read_ur_csvs(paths: Iterable[Path | str], *, bounds: PhysicalBounds = DEFAULT_BOUNDS) -> list[URRecording]:
    """Each file's recording, in the order given (the first file that cannot be used raises)."""
    out = [read_ur_csv(p, bounds=bounds) for p in paths]
    if not out:
        raise URCsvError("(no files)", None, "no recording given")
    return out
