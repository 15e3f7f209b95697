"""Console for benchmark tables: wide tables stay whole when stdout is a file or a pipe."""
from __future__ import annotations

from rich.console import Console

PIPE_WIDTH = 220  # rich falls back to 80 columns off a terminal, which folds every wide table


def table_console() -> Console:
    console = Console()
    return console if console.is_terminal else Console(width=PIPE_WIDTH)
