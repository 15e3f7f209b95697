"""The one error a UR recording raises when it cannot be read at all (a row that cannot be used is
counted and skipped instead: ``URRecording.skipped``)."""
from __future__ import annotations

from ftc_hw.record.reader import RecordingError


class URCsvError(RecordingError):
    """A file that is not a UR recording one can use: no header, no ``timestamp``, no ``actual_q`` /
    ``actual_qd``, RTDE's binary form, no usable row. The message names the file and, where there is
    one, the line (1-based)."""

    def __init__(self, path: str, line: int | None, problem: str) -> None:
        self.path = str(path)
        self.line = line
        self.problem = problem
        where = f"{self.path}:{line}: " if line is not None else f"{self.path}: "
        super().__init__(where + problem)

    def __reduce__(self):  # picklable whole, like SceneError (a worker process may raise it)
        return type(self), (self.path, self.line, self.problem)
