"""docs/cli.md is what the CLI says about itself now (ftc_hw/cli/reference.py renders it).

When this fails, regenerate the page: ``.venv/bin/python -m ftc_hw.cli.reference > docs/cli.md``.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from ftc_hw.cli.reference import render

pytestmark = pytest.mark.compute  # reads a file and the command tree: nothing timed

PAGE = Path(__file__).resolve().parents[2] / "docs" / "cli.md"
REGENERATE = ".venv/bin/python -m ftc_hw.cli.reference > docs/cli.md"


def test_the_cli_page_is_the_cli():
    assert PAGE.read_text() == render(), f"docs/cli.md differs from the CLI: regenerate it with {REGENERATE}"


def test_the_page_lists_every_command_and_option():
    page = render()
    for heading in ("## `ftc monitor`", "## `ftc demo`", "### `ftc bench pipeline`", "### `ftc devices probe`"):
        assert heading in page
    assert "- `--resume-after S`" in page and "- `--device NAME.KEY=VALUE`" in page
    assert "ftc warm" not in page  # hidden


def test_the_page_does_not_depend_on_the_terminal():
    env = {**os.environ, "COLUMNS": "40", "TERM": "dumb"}
    out = subprocess.run([sys.executable, "-m", "ftc_hw.cli.reference"], capture_output=True, text=True,
                         env=env, check=True)
    assert out.stdout == render()
