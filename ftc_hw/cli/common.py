"""Shared helpers for the subcommands: scene loading with user-facing errors."""
from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import typer

from ftc_hw.scene import Scene, SceneError, load_rig_scene


def sensing_kinds(text: str | None) -> tuple[str, ...] | None:
    """``--sensing currents,flange_ft`` -> ("currents", "flange_ft"); None: the scene's own."""
    if text is None:
        return None
    return tuple(k.strip() for k in text.split(",") if k.strip())


def scene_or_exit(name: str, device_overrides: Iterable[str] = (), rig: Path | None = None,
                  sensing: str | None = None) -> Scene:
    """The scene, with a rig file's and ``--device`` overrides applied, using ``--sensing``'s kinds
    (comma-separated; None: the scene's); exit code 2 on an error."""
    try:
        return load_rig_scene(name, device_overrides, rig, sensing_kinds(sensing))
    except SceneError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
