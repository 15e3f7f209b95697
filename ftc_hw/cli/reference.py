"""``docs/cli.md``, written from the CLI itself: every command's usage, help and options as Markdown.

Regenerate after changing a command or an option::

    .venv/bin/python -m ftc_hw.cli.reference > docs/cli.md

``tests/cli/test_cli_reference.py`` fails when the page differs from what :func:`render` gives now. Only
click's public API is read (the command tree typer builds, each parameter's help record), at a fixed
width and without rich formatting, so the page depends on the options a user types and their help, not
on the terminal, nor on how the commands are implemented.
"""
from __future__ import annotations

import inspect
import re
from typing import Any

import typer

from ftc_hw.cli import app as ftc_app

WIDTH = 10_000  # no wrapping: one line per help text, whatever the terminal
HEADER = """# `ftc`: command reference

<!-- Generated from the CLI by `.venv/bin/python -m ftc_hw.cli.reference > docs/cli.md`: do not edit by hand.
     tests/cli/test_cli_reference.py fails when this page differs from the CLI. -->

Generated from the CLI (`ftc_hw/cli/reference.py`); regenerate it with
`.venv/bin/python -m ftc_hw.cli.reference > docs/cli.md`. The same text is what `ftc COMMAND --help`
prints. What each command is for: [README](../README.md) and the guides it links.
"""
_MARKUP = re.compile(r"\[/?(?:bold|dim|italic|red|green|yellow|blue|cyan|magenta|b|i)\]")


def _text(text: str | None) -> str:
    """A help text as one paragraph of plain text: rich markup and click's \\b markers gone."""
    if not text:
        return ""
    text = _MARKUP.sub("", inspect.cleandoc(text)).replace("\b", "")
    paragraphs = [" ".join(p.split()) for p in re.split(r"\n\s*\n", text)]
    return "\n\n".join(p for p in paragraphs if p)


def _context(command: Any, name: str, parent: Any) -> Any:
    return command.context_class(command, info_name=name, parent=parent, terminal_width=WIDTH, max_content_width=WIDTH,
                         color=False, resilient_parsing=True)


def _usage(command: Any, ctx: Any) -> str:
    return " ".join([ctx.command_path, *command.collect_usage_pieces(ctx)])


def _params(command: Any, ctx: Any) -> list[str]:
    rows = []
    for param in command.get_params(ctx):
        if getattr(param, "hidden", False) or param.name == "help":  # --help: every command has it
            continue
        record = param.get_help_record(ctx)
        if record is None:  # a plain click argument has no help record
            record = (param.human_readable_name.upper(), "[required]" if param.required else "")
        names, help_text = record
        help_text = _text(help_text)
        rows.append(f"- `{names.strip()}`" + (f": {help_text}" if help_text else ""))
    return rows


def _section(command: Any, ctx: Any, level: int) -> list[str]:
    out = [f"{'#' * level} `{ctx.command_path}`", "", "```text", _usage(command, ctx), "```", ""]
    help_text = _text(command.help)
    if help_text:
        out += [help_text, ""]
    rows = _params(command, ctx)
    if rows:
        out += [*rows, ""]
    if hasattr(command, "list_commands"):  # a group: its commands, in their order
        names = [n for n in command.list_commands(ctx) if not command.get_command(ctx, n).hidden]
        out += ["Commands: " + ", ".join(f"`{ctx.command_path} {n}`" for n in names) + ".", ""]
        for name in names:
            sub = command.get_command(ctx, name)
            out += _section(sub, _context(sub, name, ctx), 2 if ctx.parent is None else 3)
    return out


def render(app: typer.Typer = ftc_app, name: str = "ftc") -> str:
    """The whole reference as Markdown: the top command, then each command and subcommand in order."""
    root = typer.main.get_command(app)
    lines = [*HEADER.splitlines(), "", *_section(root, _context(root, name, None), 2)]
    return "\n".join(line.rstrip() for line in lines).rstrip() + "\n"


if __name__ == "__main__":  # pragma: no cover - the regeneration command
    import sys

    sys.stdout.write(render())
