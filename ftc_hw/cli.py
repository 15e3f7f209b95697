"""The ``ftc`` command. Subcommands live in ``ftc_hw/commands``; heavy imports happen inside them."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from . import __version__

app = typer.Typer(no_args_is_help=True, add_completion=False, pretty_exceptions_enable=False,
                  help="ftc-hw: where, in which direction and how hard a robot arm was touched, "
                       "from one 6-axis force/torque sensor.")
bench_app = typer.Typer(no_args_is_help=True, help="Benchmarks: print a table, --json writes the figures.")
app.add_typer(bench_app, name="bench")


def _version(value: bool) -> None:
    if value:
        typer.echo(f"ftc-hw {__version__}")
        raise typer.Exit()


@app.callback()
def main(
    version: Annotated[Optional[bool], typer.Option("--version", callback=_version, is_eager=True,  # noqa: UP045
                                                    help="Print the version and exit.")] = None,
) -> None:
    """ftc-hw command line."""


@app.command()
def scenes() -> None:
    """List the built-in scenes, one line each."""
    from .commands.scenes import list_scenes

    list_scenes()


@app.command()
def sim(
    scene: Annotated[Optional[str], typer.Argument(help="Built-in scene name or path to a scene TOML.")] = None,  # noqa: UP045
    scenario: Annotated[str, typer.Option(help="Scenario name (see --list).")] = "static-pokes",
    duration: Annotated[float, typer.Option(min=0.0, help="Simulated seconds to run.")] = 10.0,
    seed: Annotated[int, typer.Option(help="Random seed: same seed, same run.")] = 0,
    truth: Annotated[Optional[Path], typer.Option(help="Write ground truth, one JSON line per sensor sample.")] = None,  # noqa: UP045
    realtime: Annotated[bool, typer.Option("--realtime/--fast", help="Pace the world to the wall clock.")] = True,
    noise: Annotated[bool, typer.Option("--noise/--no-noise", help="Sensor noise on or off.")] = True,
    list_: Annotated[bool, typer.Option("--list", help="List the scenarios and exit.")] = False,
    devices: Annotated[bool, typer.Option("--devices/--no-devices",
                                          help="Start the scene's device emulators.")] = True,
) -> None:
    """Run the physics world of a scene: device signals and ground truth."""
    from .commands.sim import list_scenarios, run_sim

    if list_:
        list_scenarios()
        return
    if scene is None:
        raise typer.BadParameter("give a scene (ftc scenes lists them) or --list", param_hint="SCENE")
    run_sim(scene, scenario, duration, seed, truth, realtime, noise, devices)


@app.command()
def solve(
    scene: Annotated[str, typer.Option(help="Built-in scene name or scene file.")],
    method: Annotated[str, typer.Option(help="ours or leng2016 (the reference paper's method).")] = "ours",
    input_path: Annotated[str, typer.Option("--input", help="JSON Lines file, or - for stdin.")] = "-",
    output_path: Annotated[str, typer.Option("--output", help="JSON Lines file, or - for stdout.")] = "-",
    bias: Annotated[Optional[str], typer.Option(help="Sensor bias to subtract, JSON list of 6 (N, N m).")] = None,  # noqa: UP045
) -> None:
    """Localize contacts: one JSON line in ({"q", "wrench", ...}), one estimate or error line out."""
    from .commands.solve import run_solve

    if method not in ("ours", "leng2016"):
        raise typer.BadParameter("ours or leng2016", param_hint="--method")
    run_solve(scene, method, input_path, output_path, bias)


@bench_app.command("bus")
def bench_bus(
    json_path: Annotated[Optional[Path], typer.Option("--json", help="Write the figures to this JSON file.")] = None,  # noqa: UP045
    frames: Annotated[int, typer.Option(min=1000, help="Frames per throughput run.")] = 200_000,
) -> None:
    """Bus throughput (publish to deliver, 1 and 4 subscribers) and sample_at latency."""
    from .bus.bench import run

    run(json_path=json_path, frames=frames)


@app.command()
def demo(
    scene: Annotated[str, typer.Option(help="Built-in scene or scene file.")] = "ur5e",
    scenario: Annotated[str, typer.Option(help="Scenario name.")] = "sweep-with-collision",
    duration: Annotated[float, typer.Option(min=1.0, help="Seconds of live view.")] = 20.0,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
) -> None:
    """The live monitor on emulated devices, then a summary. Ends by itself."""
    from .commands.demo import run_demo

    raise typer.Exit(run_demo(scene, scenario, duration, seed))


@bench_app.command("solver")
def bench_solver(
    json_path: Annotated[Optional[Path], typer.Option("--json", help="Write the figures to this JSON file.")] = None,  # noqa: UP045
    plot: Annotated[Optional[Path], typer.Option(help="Draw error against latency to this PNG.")] = None,  # noqa: UP045
    cases: Annotated[int, typer.Option(min=100, help="Sampled contacts per scene.")] = 2000,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    scene: Annotated[Optional[list[str]], typer.Option(help="Scene(s) to run (default: every built-in).")] = None,  # noqa: UP045
) -> None:
    """Solver accuracy (noise-free and with the scene's noise) against latency, ours vs leng2016."""
    from .solver.bench import run

    run(json_path=json_path, plot_path=plot, n=cases, seed=seed, scenes=scene)


@bench_app.command("compensation")
def bench_compensation(
    json_path: Annotated[Optional[Path], typer.Option("--json", help="Write the figures to this JSON file.")] = None,  # noqa: UP045
    plot: Annotated[Optional[Path], typer.Option(help="Draw error against cost to this PNG.")] = None,  # noqa: UP045
    minutes: Annotated[float, typer.Option(min=0.05, help="Simulated minutes per scenario and speed.")] = 1.0,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    scene: Annotated[Optional[list[str]], typer.Option(help="Scene(s) to run (default: every built-in).")] = None,  # noqa: UP045
) -> None:
    """Compensation levels on moving sweeps: free-motion error, false alarms, detection delay, cost."""
    from .compensation.bench import run

    run(json_path=json_path, plot_path=plot, minutes=minutes, seed=seed, scenes=scene)


@bench_app.command("devices")
def bench_devices(
    json_path: Annotated[Optional[Path], typer.Option("--json", help="Write the figures to this JSON file.")] = None,  # noqa: UP045
    duration: Annotated[float, typer.Option(min=1.0, help="Seconds per streaming run.")] = 60.0,
) -> None:
    """F/T adapters against their emulators: rates, loss, corruption, reconnects."""
    from devices.bench import run

    run(json_path=json_path, duration=duration)


@bench_app.command("arms")
def bench_arms(
    json_path: Annotated[Optional[Path], typer.Option("--json", help="Write the figures to this JSON file.")] = None,  # noqa: UP045
    duration: Annotated[float, typer.Option(min=1.0, help="Seconds per streaming run.")] = 60.0,
) -> None:
    """Arm adapters against their emulators: RTDE rate and accuracy, Dynamixel reads, stop, reconnects."""
    from devices.arm_bench import run

    run(json_path=json_path, duration=duration)


def run() -> None:  # pragma: no cover - console entry point
    app()
