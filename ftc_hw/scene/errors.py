"""Typed errors for scene files."""
from __future__ import annotations

from pathlib import Path


class SceneError(ValueError):
    """A scene file is missing, unreadable or malformed.

    The message names the file, the key (dotted TOML path) and what was expected.
    """

    def __init__(self, path: Path | str, key: str, problem: str) -> None:
        self.path = str(path)
        self.key = key
        self.problem = problem
        where = f"{self.path}: {key}: " if key else f"{self.path}: "
        super().__init__(where + problem)

    def __reduce__(self):  # pickled whole: a bench's worker process raises it to the parent
        return type(self), (self.path, self.key, self.problem)
