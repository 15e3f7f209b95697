"""``ftc ros ...``: the options checked, one call into ``ftc_hw.app.ros``, its outcome as an exit code.
Without the ``ros`` extra every ROS command says what to install (exit code 1)."""
from __future__ import annotations

from typing import Any

import typer

from ftc_hw.app.ros import RosUnavailable, require_ros
from ftc_hw.sim_devices.world import SCENARIOS


def run_publish_command(**options: Any) -> int:
    """``ftc ros publish``: 0 when it ran to its end, 130 on Ctrl-C, 1 when it cannot start, 2 on bad options."""
    if options["sim"] and options["scenario"] not in SCENARIOS:
        typer.echo(f"error: unknown scenario {options['scenario']!r} (known: {', '.join(SCENARIOS)})", err=True)
        return 2
    try:
        require_ros("ftc ros publish")
        from ftc_hw.app.ros.publish import PublishError, PublishOptions, run_publish  # lazy: rclpy, the ros extra
    except RosUnavailable as exc:
        typer.echo(f"error: {exc}", err=True)
        return 1
    try:
        out = run_publish(PublishOptions(**options))
    except PublishError as exc:
        typer.echo(f"error: {exc}", err=True)
        return 1
    counts = ", ".join(f"{topic} {n}" for topic, n in out.published.items()) or "nothing"
    typer.echo(f"published: {counts}" + (f" ({out.stopped_by})" if out.stopped_by else ""), err=True)
    if out.stop_service:
        typer.echo(f"{out.stop_service}: {out.stop_calls} calls, {out.stop_failures} failed", err=True)
    for name, counters in out.device_counters.items():
        typer.echo(f"{name}: {counters}", err=True)
    return 130 if out.stopped_by else 0
