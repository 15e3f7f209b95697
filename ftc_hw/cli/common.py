"""Shared helpers for the subcommands: scene loading with user-facing errors."""
from __future__ import annotations

import typer

from ftc_hw.scene import Scene, SceneError, load_scene


def scene_or_exit(name: str) -> Scene:
    try:
        return load_scene(name)
    except SceneError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
