"""The ``ftc`` command: options parsed here, the work done by the layers below.

Each command imports its implementation when it runs (``# lazy:`` below): ``ftc --help`` and a
mistyped option answer at once, without loading MuJoCo, numba kernels and the device stack.
"""
from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any, Optional

import typer
import typer.core

from ftc_hw import __version__
from ftc_hw.priority import end_process

_typed = typer.core.TyperOption.display_type_rich


def _flag_untyped(self: typer.core.TyperOption, ctx: Any) -> str | None:
    """No type for a flag, which takes no value (typer 0.29 writes ``<bool>`` after every flag in --help)."""
    return None if self.is_flag and self.metavar is None else _typed(self, ctx)


typer.core.TyperOption.display_type_rich = _flag_untyped  # type: ignore[method-assign]

app = typer.Typer(no_args_is_help=True, add_completion=False, pretty_exceptions_enable=False,
                  help="ftc-hw: where, in which direction and how hard a robot arm was touched, "
                       "from one 6-axis force/torque sensor.")


class Method(StrEnum):
    """A contact localization method."""

    ours = "ours"
    leng2016 = "leng2016"  # the reference paper's


class Level(StrEnum):
    """A compensation level (``scene``: the one the scene file declares)."""

    dynamics = "dynamics"
    gravity = "gravity"
    bias = "bias"
    scene = "scene"


class Reflex(StrEnum):
    stop = "stop"
    retreat = "retreat"


class RecordFormat(StrEnum):
    ftc = "ftc"
    ros2 = "ros2"
    both = "both"


class RetreatOn(StrEnum):
    """What starts a retreat: a contact's onset, or its force past its body region's limit (docs/limits.md)."""

    onset = "onset"
    exceedance = "exceedance"


class Readers(StrEnum):
    """Where the devices' readers run: each in its own process (as ftc serve runs them), in threads here,
    or auto (processes, except with --sim on a host of fewer than 4 cores)."""

    auto = "auto"
    process = "process"
    thread = "thread"


class RealityChoice(StrEnum):
    """How the simulated world's arm differs from the model (docs/reality.md)."""

    ideal = "ideal"
    typical = "typical"
    harsh = "harsh"


class View(StrEnum):
    """Where the live view goes: the terminal's table, a page in the browser (docs/monitor.md), none."""

    terminal = "terminal"
    web = "web"
    none = "none"


class BusTransport(StrEnum):
    inproc = "inproc"
    zenoh = "zenoh"


class BenchWorld(StrEnum):
    """A bench's simulated world: computed ahead and played from memory, or stepped live."""

    ahead = "ahead"
    live = "live"


class BenchCores(StrEnum):
    """Where a real-time leg runs: the simulated cell and the monitor on cores apart, or all on every core."""

    split = "split"
    shared = "shared"


def reality_option(default: RealityChoice, what: str = "") -> Any:
    return typer.Option(help=f"{what}The simulated world: ideal (the model itself), typical or harsh (seeded draws "
                             "of a real arm's, sensor's and shell's differences from the model; docs/reality.md).")


LOADING = "loading MuJoCo, numba and the device stack ..."  # seconds, before a live command's first line

bench_app = typer.Typer(no_args_is_help=True, help="Benchmarks: print a table, --json writes the figures.")
app.add_typer(bench_app, name="bench")
devices_app = typer.Typer(no_args_is_help=True, help="Real devices: what answers where.")
app.add_typer(devices_app, name="devices")
ros_app = typer.Typer(no_args_is_help=True, help="ROS 2 (the ros extra; docs/ros.md).")
app.add_typer(ros_app, name="ros")

# Pointing a scene at one's own devices (monitor, calibrate): docs/hardware.md
DeviceOption = Annotated[Optional[list[str]], typer.Option(  # noqa: UP045
    "--device", metavar="NAME.KEY=VALUE", help="Where a scene device is, or one of its params, e.g. "
    "ft.address=/dev/ttyUSB0, ft.channel=/dev/ttyACM0 (CAN), arm.address=192.168.1.10, arm.baudrate=57600; "
    "repeatable, applied after --rig.")]
ZenohConfigOption = Annotated[Optional[Path], typer.Option(  # noqa: UP045
    "--zenoh-config", metavar="FILE.json5", exists=True, dir_okay=False,
    help="A Zenoh configuration file under the session: TLS, user-password credentials, access control "
         "(docs/bus.md).")]
SensingOption = Annotated[Optional[str], typer.Option(  # noqa: UP045
    metavar="KIND,...", help="Which of the scene's sensing to use: base_ft, flange_ft, joint_torques, currents, "
    "comma-separated (default: the scene's own; docs/scenes.md, Sensing). Without base_ft the arm is judged "
    "(and identified) from its joints.")]
TopicsOption = Annotated[Optional[Path], typer.Option(  # noqa: UP045
    "--topics", metavar="MAP.toml", help="A ROS 2 bag's topic map: which topic is the joint states (effort as "
    "current or torque, the driver's joint names to the scene's), which the wrench and its frame (default: the "
    "drivers' defaults for the scene's arm; docs/ros.md, Bags in).")]
RigOption = Annotated[Optional[Path], typer.Option(  # noqa: UP045
    "--rig", metavar="FILE.toml", help="A rig file: a [NAME] table per scene device with the --device keys.")]
LimitsOption = Annotated[Optional[Path], typer.Option(  # noqa: UP045
    metavar="FILE", help="The cell's body limits (TOML: body regions to links and workspace zones, docs/limits.md); "
    "every contact event carries its margin to its region's limit, an exceedance is an event of its own. "
    "Default: the built-in ISO/TS 15066 regions, every link the default region.")]
# monitor, demo, replay: the live page
ViewOption = Annotated[View, typer.Option(
    help="The live view: terminal (a table), web (a 3-D page in the browser, served on --host:--port; "
         "docs/monitor.md) or none.")]
# a flag takes no value: no type in the help's column (typer shows <bool> there otherwise)
NoViewOption = Annotated[bool, typer.Option("--no-view", metavar="", help="The same as --view none.")]
HostOption = Annotated[str, typer.Option(help="With --view web: the address the page listens on (another "
                                         "than loopback makes it reachable from the network).")]
PortOption = Annotated[int, typer.Option(min=1, max=65535, help="With --view web: the page's port (when taken: the "
                                         "next free one; the printed URL says which).")]
ViewHzOption = Annotated[float, typer.Option(min=0.5, max=60.0, help=(
    "With --view web: the page's updates a second (the arm's pose; the plots and text once a second; an "
    "onset at once). Each update makes a browser without a GPU render in software: keep it low when the "
    "browser shares the monitor's host (docs/monitor.md); the page slows down by itself, down to 1 Hz, while "
    "the monitor falls behind."))]
# calibrate, identify
PLOT_HELP = "Draw the fit (residuals, parameters with error bars) to a PNG beside the calibration file."


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
def scenes(
    fetch_meshes: Annotated[bool, typer.Option(
        "--fetch-meshes", help="Fetch the vendor meshes the built-in scenes name (the simulated world's true "
        "shell; ~/.cache/ftc-hw/vendor or $FTC_VENDOR_DIR), then list.")] = False,
) -> None:
    """List the built-in scenes, one line each."""
    from ftc_hw.cli.scenes import fetch_all_meshes, list_scenes  # lazy: CLI start-up

    if fetch_meshes:
        fetch_all_meshes()
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
    address: Annotated[Optional[list[str]], typer.Option(  # noqa: UP045
        metavar="DEVICE=ADDR", help="Where an emulator listens: a loopback IP for a UR arm (arm=127.0.0.3) or a "
        "Modbus TCP device (host[:port]), a pty path for a serial or CAN device; repeatable.")] = None,
    reality: Annotated[RealityChoice, reality_option(RealityChoice.ideal)] = RealityChoice.ideal,
    device: Annotated[Optional[list[str]], typer.Option(  # noqa: UP045
        "--device", metavar="NAME.KEY=VALUE", help="A scene device's param for its emulator, e.g. "
        "arm.baudrate=57600, arm.bus_time=false (a DYNAMIXEL chain answers without the bus's time: speed "
        "tests only); repeatable.")] = None,
    world_ahead: Annotated[bool, typer.Option(
        "--world-ahead", help="Compute the whole run first (as fast as it goes), then serve it from memory on the "
        "wall clock: the emulators cost only their sockets. Commands (a stop) are recorded, not obeyed: the arm "
        "goes on as computed (docs/monitor.md).")] = False,
) -> None:
    """Run the physics world of a scene: device signals and ground truth. Ctrl-C stops it (exit code 130)."""
    from ftc_hw.cli.sim import list_scenarios, run_sim  # lazy: CLI start-up

    if list_:
        list_scenarios()
        return
    if scene is None:
        raise typer.BadParameter("give a scene (ftc scenes lists them) or --list", param_hint="SCENE")
    if world_ahead and not realtime:
        raise typer.BadParameter("a world computed ahead is played in real time: not with --fast",
                                 param_hint="--world-ahead")
    run_sim(scene, scenario, duration, seed, truth, realtime, noise, devices, address or [], reality.value,
            device or [], world_ahead)


@app.command()
def solve(
    scene: Annotated[str, typer.Option(help="Built-in scene name or scene file.")],
    method: Annotated[Method, typer.Option(help="Localization method (leng2016: the paper's).")] = Method.ours,
    input_path: Annotated[str, typer.Option("--input", help="JSON Lines file, or - for stdin.")] = "-",
    output_path: Annotated[str, typer.Option("--output", help="JSON Lines file, or - for stdout.")] = "-",
    bias: Annotated[Optional[str], typer.Option(help="Sensor bias to subtract, JSON list of 6 (N, N m).")] = None,  # noqa: UP045
    sensing: SensingOption = None,
) -> None:
    """Localize contacts: one JSON line in ({"q", "wrench", ...}; a scene sensed through its joints: {"q",
    "tau_ext", "tau_ext_std"}), one estimate or error line out."""
    from ftc_hw.cli.solve import run_solve  # lazy: CLI start-up

    run_solve(scene, method.value, input_path, output_path, bias, sensing)


@bench_app.command("bus")
def bench_bus(
    json_path: Annotated[Optional[Path], typer.Option("--json", help="Write the figures to this JSON file.")] = None,  # noqa: UP045
    frames: Annotated[int, typer.Option(min=1000, help="Frames per throughput run.")] = 200_000,
    transport: Annotated[BusTransport, typer.Option(help="inproc: one process; zenoh: also between processes "
                                                   "on Zenoh (1 and 4 subscriber processes, loopback).")]
    = BusTransport.inproc,
) -> None:
    """Bus throughput (publish to deliver, 1 and 4 subscribers) and sample_at latency."""
    from ftc_hw.bench.bus import run  # lazy: CLI start-up

    run(json_path=json_path, frames=frames, transport=transport.value)


@app.command()
def demo(
    scene: Annotated[str, typer.Option(help="Built-in scene or scene file.")] = "ur5e",
    scenario: Annotated[str, typer.Option(help="Scenario name.")] = "sweep-with-collision",
    duration: Annotated[float, typer.Option(min=1.0, help="Simulated seconds (real time) of live view.")] = 30.0,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    record: Annotated[Optional[Path], typer.Option(help="Also record the run to this MCAP file.")] = None,  # noqa: UP045
    reality: Annotated[RealityChoice, reality_option(RealityChoice.typical)] = RealityChoice.typical,
    sensing: SensingOption = None,
    identify_seconds: Annotated[float, typer.Option(
        min=0.0, help="In a typical or harsh world: seconds of planned excitation the drawn arm is identified from "
                      "first (ftc identify --sim --plan); 0 monitors it with the nominal model.")] = 30.0,
    view: ViewOption = View.terminal,
    host: HostOption = "127.0.0.1",
    port: PortOption = 8080,
    view_hz: ViewHzOption = 10.0,
) -> None:
    """Emulated devices, a collision scenario, the live monitor, then contacts against ground truth. Ends by itself."""
    if 0 < identify_seconds < 5:
        raise typer.BadParameter("0 (no identification) or at least 5", param_hint="--identify-seconds")
    typer.echo(LOADING, err=True)
    from ftc_hw.app.demo import run_demo  # lazy: CLI start-up
    from ftc_hw.app.monitor.config import DemoOptions, MonitorOptions, SimOptions  # lazy: CLI start-up
    from ftc_hw.app.monitor.view import make_console  # lazy: CLI start-up
    from ftc_hw.cli.common import sensing_kinds  # lazy: CLI start-up
    from ftc_hw.cli.monitor import outcome_or_exit, view_options  # lazy: CLI start-up

    options = DemoOptions(MonitorOptions(scene, sensing_kinds(sensing), sim=True,
                                         world=SimOptions(scenario, seed, reality.value),
                                         duration=duration, record=record,
                                         view=view_options(view.value, host, port, view_hz), title="ftc demo"),
                          identify_s=identify_seconds)
    raise typer.Exit(outcome_or_exit(lambda: run_demo(options, make_console())).exit_code)


@app.command()
def monitor(
    scene: Annotated[str, typer.Option(help="Built-in scene name or scene file.")],
    sim: Annotated[bool, typer.Option("--sim", metavar="", help="Start the scene's emulated devices (what ftc sim "
                                      "starts) and connect to them.")] = False,
    scenario: Annotated[str, typer.Option(help="With --sim: the scenario (ftc sim --list).")] = "sweep-with-collision",
    seed: Annotated[int, typer.Option(help="With --sim: random seed.")] = 0,
    duration: Annotated[Optional[float], typer.Option(min=0.1, help="Seconds to run (simulated seconds with --sim); "  # noqa: UP045
                                                      "default: until Ctrl-C.")] = None,
    calibration: Annotated[Optional[Path], typer.Option(help="Calibration file (ftc calibrate): bias and payload; "  # noqa: UP045
                                                        "without one the sensor is tared on the first 0.1 s.")] = None,
    record: Annotated[Optional[Path], typer.Option(help="Record every bus topic to this MCAP file.")] = None,  # noqa: UP045
    record_format: Annotated[RecordFormat, typer.Option(
        help="What --record writes: ftc (MCAP of the bus's channels, which ftc replay reads), ros2 (a ROS 2 bag "
             "directory at the path: the drivers' topics, the outputs of --ros and /tf; needs the ros extra), "
             "both (the ftc file, and the bag beside it as STEM_ros2/; docs/ros.md).")] = RecordFormat.ftc,
    ros: Annotated[bool, typer.Option("--ros", metavar="", help="Publish the outputs on ROS 2 (external wrench, "
                                      "contact pose and wrench, markers, events, /diagnostics; docs/ros.md); "
                                      "needs the ros extra.")] = False,
    ros_namespace: Annotated[str, typer.Option(help="With --ros: the outputs' namespace.")] = "/ftc",
    reflex: Annotated[Optional[Reflex], typer.Option(help="stop: a contact onset commands the arm to stop; retreat: it "  # noqa: UP045
                                                     "moves the touched point back along the contact normal (the "
                                                     "reverse of its motion; on a still arm, the force's direction) "
                                                     "through the arm's protocol; a guided contact is left alone.")
                 ] = None,
    retreat_distance: Annotated[float, typer.Option(min=0.001, max=0.5, metavar="M", help="With --reflex retreat: "
                                                    "how far the touched point -- every point the contact may be at "
                                                    "-- moves back (m).")] = 0.03,
    retreat_time: Annotated[float, typer.Option(min=0.01, max=10.0, metavar="S", help="With --reflex retreat: the "
                                                "time the motion must end within (s); a motion the joints' limits "
                                                "make longer is cut to end in time, and said (a retreat_short "
                                                "event).")] = 0.5,
    retreat_on: Annotated[RetreatOn, typer.Option(help="With --reflex retreat: what starts one, a contact's onset or "
                                                  "its exceedance of the body limits (--limits).")] = RetreatOn.onset,
    resume_after: Annotated[Optional[float], typer.Option(  # noqa: UP045
        min=0.0, metavar="S", help="With --sim and a UR arm: the emulated controller's operator presses play S s "
        "after each stop, and the arm goes on with the scenario where it stopped (with --reflex stop, every "
        "contact of a sweep meets a stop).")] = None,
    world_ahead: Annotated[bool, typer.Option(
        "--world-ahead", metavar="", help="With --sim and --duration: compute the world's run first, then serve it "
        "to the emulators from memory on the wall clock (the simulated cell costs only its sockets). A stop is "
        "recorded at the arm's interface and not obeyed: the arm goes on as computed.")] = False,
    events: Annotated[Optional[Path], typer.Option(help="Write contact events, one JSON line each.")] = None,  # noqa: UP045
    limits: LimitsOption = None,
    truth: Annotated[Optional[Path], typer.Option(help="With --sim: write the world's ground truth.")] = None,  # noqa: UP045
    noise: Annotated[bool, typer.Option("--noise/--no-noise", metavar="", help="With --sim: sensor noise.")] = True,
    view: ViewOption = View.terminal,
    no_view: NoViewOption = False,
    host: HostOption = "127.0.0.1",
    port: PortOption = 8080,
    view_hz: ViewHzOption = 10.0,
    level: Annotated[Level, typer.Option(help="Compensation level: dynamics (the arm moves), gravity, bias, or "
                                         "scene (the level the scene file declares).")] = Level.dynamics,
    fault: Annotated[Optional[list[str]], typer.Option(  # noqa: UP045
        help="With --sim: DEVICE:ACTION@WHEN, repeatable, in order: ACTION kill, restart or stall:S; WHEN a scenario "
             "time T, +S after the previous fault, or onset+S (docs/monitor.md).")] = None,
    device: DeviceOption = None,
    rig: RigOption = None,
    sensing: SensingOption = None,
    reality: Annotated[RealityChoice, reality_option(RealityChoice.ideal, "With --sim: ")] = RealityChoice.ideal,
    refine: Annotated[bool, typer.Option("--refine", metavar="", help="Keep refining the calibration's identified "
                                         "model (ftc identify) while the arm moves free, and say at the end how far "
                                         "it drifted (docs/reality.md).")] = False,
    remote: Annotated[Optional[str], typer.Option(  # noqa: UP045
        metavar="ENDPOINT", help="Take the devices' frames from ftc serve at this Zenoh endpoint (e.g. "
        "tcp/127.0.0.1:7447) instead of opening them here; the contact events go back there (docs/bus.md).")] = None,
    remote_name: Annotated[Optional[str], typer.Option(  # noqa: UP045
        help="With --remote: the rig's name in ftc/NAME/... (default: the scene's name, as ftc serve).")] = None,
    zenoh_config: ZenohConfigOption = None,
    readers: Annotated[Readers, typer.Option(
        help="process: each device's reader in its own process, its frames over Zenoh on loopback (nothing the "
             "pipeline computes can make it miss a packet); thread: in this process; auto: process, except with "
             "--sim on a host of fewer than 4 cores, whose cores the simulated world needs (docs/bus.md).")
    ] = Readers.auto,
) -> None:
    """Live collision monitor: the scene's devices, compensation, detection, localization, events."""
    typer.echo(LOADING, err=True)
    from ftc_hw.app.monitor.config import DeviceOptions, MonitorOptions, SimOptions  # lazy: CLI start-up
    from ftc_hw.app.monitor.config import RetreatSettings as Retreat  # lazy: CLI start-up
    from ftc_hw.app.monitor.session import run_monitor  # lazy: CLI start-up
    from ftc_hw.app.monitor.view import make_console  # lazy: CLI start-up
    from ftc_hw.cli.monitor import check_monitor, outcome_or_exit, view_options  # lazy: CLI start-up

    world = SimOptions(scenario=scenario, seed=seed, reality=reality.value, noise=noise, truth=truth,
                       faults=tuple(fault or ()), resume_after_s=resume_after, ahead=world_ahead)
    devices = DeviceOptions(overrides=tuple(device or ()), rig=rig, remote=remote, remote_rig=remote_name,
                            zenoh_config=zenoh_config, readers=readers.value)
    from ftc_hw.cli.common import sensing_kinds  # lazy: CLI start-up

    options = MonitorOptions(scene, sensing_kinds(sensing), sim=sim, world=world, duration=duration,
                             calibration=calibration,
                             level=None if level is Level.scene else level.value, refine=refine, record=record,
                             record_format=record_format.value, ros_namespace=ros_namespace if ros else None,
                             events=events, reflex=reflex.value if reflex else None, limits=limits,
                             retreat=Retreat(distance_m=retreat_distance, time_limit_s=retreat_time,
                                             trigger=retreat_on.value),
                             view=view_options((View.none if no_view else view).value, host, port, view_hz),
                             devices=devices)
    check_monitor(options)
    raise typer.Exit(outcome_or_exit(lambda: run_monitor(options, make_console())).exit_code)


@app.command()
def replay(
    path: Annotated[Path, typer.Argument(help="An MCAP file recorded by ftc monitor --record, a UR recording "
                                         "(the CSV of UR's RTDE client or of ur_rtde; with --scene), or a ROS 2 bag "
                                         "(MCAP or sqlite3, the bag's folder or file; with --scene, --topics).")],
    speed: Annotated[float, typer.Option(min=0.0, help="Pace: 1 = as recorded, 0 = as fast as possible.")] = 1.0,
    events: Annotated[Optional[Path], typer.Option(help="Write the replayed events, one JSON line each.")] = None,  # noqa: UP045
    calibration: Annotated[Optional[Path], typer.Option(help="Replay with this calibration instead.")] = None,  # noqa: UP045
    limits: Annotated[Optional[Path], typer.Option(  # noqa: UP045
        metavar="FILE", help="Judge the contacts against this cell's body limits (TOML, docs/limits.md) instead of "
        "the recorded ones (a recording made without: none).")] = None,
    check: Annotated[bool, typer.Option("--check", metavar="",
                                        help="Exit 1 when the events differ from the recorded.")] = False,
    view: Annotated[View, typer.Option(
        help="terminal: the live table while it replays (with --speed > 0); web: the replay then a 3-D page over it "
             "with play/pause and a time slider, served until Ctrl-C (docs/monitor.md); none.")] = View.terminal,
    no_view: NoViewOption = False,
    host: HostOption = "127.0.0.1",
    port: PortOption = 8080,
    view_hz: Annotated[float, typer.Option(min=0.5, max=60.0, help=(
        "With --view web: the page's updates a second of the recording's time (the arm's pose; the plots and "
        "text once a second)."))] = 10.0,
    scene: Annotated[Optional[str], typer.Option(help="A UR recording's or a ROS 2 bag's scene (ur10e, ur5e, fr3, "  # noqa: UP045
                                                 "... or a file).")] = None,
    sensing: SensingOption = None,
    topics: TopicsOption = None,
) -> None:
    """Feed a recording through the same pipeline; compare the events with the recorded ones."""
    from ftc_hw.app.monitor.config import ReplayOptions  # lazy: CLI start-up
    from ftc_hw.cli.common import sensing_kinds  # lazy: CLI start-up
    from ftc_hw.cli.monitor import replay_exit_code, view_options  # lazy: CLI start-up

    shown = view_options((View.none if no_view else view).value, host, port, view_hz)
    options = ReplayOptions(path, speed, events, calibration, shown, scene=scene, sensing=sensing_kinds(sensing),
                            topics=topics, limits=limits)
    raise typer.Exit(replay_exit_code(options, check))


@app.command()
def report(
    path: Annotated[Path, typer.Argument(help="An MCAP file recorded by ftc monitor --record.")],
    out: Annotated[Optional[Path], typer.Option(help="The page (default: beside the recording, .html).")] = None,  # noqa: UP045
    limits: Annotated[Optional[Path], typer.Option(  # noqa: UP045
        metavar="FILE", help="Judge the contacts against this cell's body limits (TOML, docs/limits.md), replaying "
        "the recording; default: its recorded judgement, or the built-in regions where it has none.")] = None,
) -> None:
    """One HTML page of a run's contacts against the body limits: force over time against the limit, class,
    margin, effective mass, speed against the permissible speed, where on the arm (readable offline)."""
    typer.echo(LOADING, err=True)
    from ftc_hw.app.monitor.run_report import ReportError, write_report  # lazy: CLI start-up (MuJoCo, matplotlib)

    try:
        page = write_report(path, out, limits)
    except ReportError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(1) from None
    typer.echo(f"report: {page}")


@bench_app.command("solver")
def bench_solver(
    json_path: Annotated[Optional[Path], typer.Option("--json", help="Write the figures to this JSON file.")] = None,  # noqa: UP045
    plot: Annotated[Optional[Path], typer.Option(help="Draw error against latency to this PNG.")] = None,  # noqa: UP045
    cases: Annotated[int, typer.Option(min=100, help="Sampled contacts per scene.")] = 2000,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    scene: Annotated[Optional[list[str]], typer.Option(help="Scene(s) to run (default: every built-in).")] = None,  # noqa: UP045
    method: Annotated[Optional[list[Method]], typer.Option(  # noqa: UP045
        help="Method(s) to run (default: ours and leng2016; leng2016 takes ms to 100s of ms a frame).")] = None,
    magnitude_cases: Annotated[int, typer.Option(
        min=0, help="Also compare the force magnitude with |f_measured| (leng2016's) on this many cases per "
                    "scene (batch path, ours only; 100000 resolves the difference), in the JSON as "
                    "'magnitude_vs_force_reading'.")] = 0,
) -> None:
    """Solver accuracy (noise-free and with the scene's noise) against latency, ours vs leng2016."""
    from ftc_hw.bench.solver import run  # lazy: CLI start-up

    methods = tuple(m.value for m in method) if method else ("ours", "leng2016")
    if 0 < magnitude_cases < 100:
        raise typer.BadParameter("0 (off) or at least 100", param_hint="--magnitude-cases")
    run(json_path=json_path, plot_path=plot, n=cases, seed=seed, scenes=scene, methods=methods,
        magnitude_cases=magnitude_cases)


@bench_app.command("geometry")
def bench_geometry(
    json_path: Annotated[Optional[Path], typer.Option("--json", help="Write the figures to this JSON file.")] = None,  # noqa: UP045
    lines: Annotated[int, typer.Option(min=100, help="Random lines (or points) per call.")] = 100_000,
) -> None:
    """The geometry engine: line crossings, inside tests and closest points per second, per primitive."""
    from ftc_hw.bench.geometry import run  # lazy: CLI start-up

    run(json_path=json_path, lines=lines)


@bench_app.command("compensation")
def bench_compensation(
    json_path: Annotated[Optional[Path], typer.Option("--json", help="Write the figures to this JSON file.")] = None,  # noqa: UP045
    plot: Annotated[Optional[Path], typer.Option(help="Draw error against cost to this PNG.")] = None,  # noqa: UP045
    minutes: Annotated[float, typer.Option(min=0.05, help="Simulated minutes per scenario and speed.")] = 1.0,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    scene: Annotated[Optional[list[str]], typer.Option(help="Scene(s) to run (default: every built-in).")] = None,  # noqa: UP045
    reality: Annotated[RealityChoice, reality_option(RealityChoice.typical)] = RealityChoice.typical,
) -> None:
    """Compensation levels on moving sweeps: free-motion error, false alarms, detection delay, cost."""
    from ftc_hw.bench.compensation import run  # lazy: CLI start-up

    run(json_path=json_path, plot_path=plot, minutes=minutes, seed=seed, scenes=scene, reality=reality.value)


@bench_app.command("pipeline")
def bench_pipeline(
    json_path: Annotated[Optional[Path], typer.Option("--json", help="Write the figures to this JSON file.")] = None,  # noqa: UP045
    scene: Annotated[Optional[list[str]], typer.Option(help="Scene(s) to run (default: ur5e, ur5e-netft).")] = None,  # noqa: UP045
    rate: Annotated[Optional[float], typer.Option(min=1.0, help="Sensor rate, Hz (default: each scene's).")] = None,  # noqa: UP045
    seconds: Annotated[float, typer.Option(min=1.0, help="Simulated seconds of the collision sweep, offline.")] = 20.0,
    realtime: Annotated[float, typer.Option(min=0.0, help="Seconds of ftc monitor --sim per scene (0: none).")] = 10.0,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    world: Annotated[BenchWorld, typer.Option(
        help="The real-time leg's world: ahead, computed first and served from memory (the emulators cost only "
             "their sockets; a stop is measured at the arm's interface and not obeyed); live, stepped in real "
             "time beside the monitor.")] = BenchWorld.ahead,
    reality: Annotated[RealityChoice, reality_option(RealityChoice.ideal, "The real-time leg's world: ")
                       ] = RealityChoice.ideal,
    calibration: Annotated[Optional[Path], typer.Option(  # noqa: UP045
        exists=True, dir_okay=False, help="The real-time leg's monitor uses this calibration (ftc identify's of "
                                          "that world; default: the scene's nominal model).")] = None,
    cores: Annotated[BenchCores, typer.Option(
        help="The real-time leg's cores: shared, every process on every core; split, the simulated world and its "
             "emulators on one core and the monitor (its threads, its recorder) on the others, as on a cell whose "
             "monitor host runs no simulator.")] = BenchCores.shared,
) -> None:
    """The pipeline's cost per frame by stage at a sensor rate, and whether it keeps up in real time."""
    from ftc_hw.bench.pipeline import RealtimeLeg, run  # lazy: CLI start-up

    leg = RealtimeLeg(realtime, world is BenchWorld.ahead, reality.value, calibration, cores is BenchCores.split)
    run(json_path=json_path, scenes=scene, rate_hz=rate, seconds=seconds, seed=seed, realtime=leg)


@bench_app.command("provisional")
def bench_provisional(
    json_path: Annotated[Optional[Path], typer.Option("--json", help="Write the figures to this JSON file.")] = None,  # noqa: UP045
    scene: Annotated[str, typer.Option(help="Scene (a base F/T sensor).")] = "ur5e",
    reality: Annotated[RealityChoice, reality_option(RealityChoice.typical)] = RealityChoice.typical,
    minutes: Annotated[float, typer.Option(min=0.1, help="Simulated minutes of the collision sweep.")] = 10.0,
    seed: Annotated[int, typer.Option(help="The world's draw.")] = 0,
    recording: Annotated[Optional[Path], typer.Option(help="Take the joint stream's arrival pattern from this "  # noqa: UP045
                                                      "recording (ftc monitor --record).")] = None,
) -> None:
    """The provisional onset offline: its false alarms and decision delay over long runs (docs/monitor.md)."""
    from ftc_hw.bench.provisional import run  # lazy: CLI start-up

    run(scene, reality=reality.value, minutes=minutes, seed=seed, recording=recording, json_path=json_path)


@bench_app.command("reality")
def bench_reality(
    json_path: Annotated[Optional[Path], typer.Option("--json", help="Write the figures to this JSON file.")] = None,  # noqa: UP045
    plot: Annotated[Optional[Path], typer.Option(help="Draw the main columns to this PNG.")] = None,  # noqa: UP045
    scene: Annotated[Optional[list[str]], typer.Option(help="Scene(s) to run (default: every built-in).")] = None,  # noqa: UP045
    draws: Annotated[int, typer.Option(min=1, help="Seeded draws of the world per column.")] = 5,
    free_minutes: Annotated[float, typer.Option(min=0.1, help="Simulated minutes of free sweep per draw.")] = 2.0,
    contact_minutes: Annotated[float, typer.Option(min=0.1, help="Simulated minutes of each contact scenario "
                                                   "per draw.")] = 1.0,
    identify_minutes: Annotated[float, typer.Option(min=0.2, help="Minutes of motion identification uses.")] = 2.0,
    costs: Annotated[bool, typer.Option("--costs/--no-costs", help="Also each difference on its own.")] = True,
    workers: Annotated[Optional[int], typer.Option(min=1, help="Processes (default: one per CPU).")] = None,  # noqa: UP045
    column: Annotated[Optional[list[str]], typer.Option(  # noqa: UP045
        help="Only the columns matching this name or glob (repeatable), e.g. ideal, 'only:*'.")] = None,
) -> None:
    """Reality gap: ideal, typical and harsh worlds, with and without identification, and each difference's cost."""
    from ftc_hw.bench.reality import ALL_COLUMNS, run, select_columns  # lazy: CLI start-up

    try:
        select_columns(ALL_COLUMNS, column)
    except ValueError as exc:
        raise typer.BadParameter(str(exc), param_hint="--column") from exc
    run(json_path=json_path, plot_path=plot, scenes=scene, draws=draws, free_minutes=free_minutes,
        contact_minutes=contact_minutes, identify_minutes=identify_minutes, costs=costs, workers=workers,
        only_columns=column)


@bench_app.command("proprio")
def bench_proprio(
    json_path: Annotated[Optional[Path], typer.Option("--json", help="Write the figures to this JSON file.")] = None,  # noqa: UP045
    draws: Annotated[int, typer.Option(min=1, help="Seeded draws of the typical world per column.")] = 2,
    free_minutes: Annotated[float, typer.Option(min=0.05, help="Simulated minutes of free sweep per draw.")] = 5.0,
    probes: Annotated[int, typer.Option(min=4, help="Probes per draw (one a second, in four force bands).")] = 40,
    identify_minutes: Annotated[float, typer.Option(min=0.0, help="Minutes of planned excitation the drawn arm "
                                                    "is identified from first (0: the nominal model).")] = 2.0,
    workers: Annotated[Optional[int], typer.Option(min=1, help="Processes (default: one per CPU).")] = None,  # noqa: UP045
    column: Annotated[Optional[list[str]], typer.Option(  # noqa: UP045
        help="Only the columns matching this name or glob (repeatable), e.g. 'ur10e: currents', 'panda*'.")] = None,
) -> None:
    """Contact sensing by what the arm senses: currents, joint torques, base or flange F/T, side by side."""
    from ftc_hw.bench.proprio import run, select  # lazy: CLI start-up

    try:
        columns = select(column)
    except ValueError as exc:
        raise typer.BadParameter(str(exc), param_hint="--column") from exc
    run(json_path, columns=columns, draws=draws, free_s=free_minutes * 60.0, n_probes=probes,
        identify_s=identify_minutes * 60.0, workers=workers)


@bench_app.command("classify")
def bench_classify(
    json_path: Annotated[Optional[Path], typer.Option("--json", help="Write the figures to this JSON file.")] = None,  # noqa: UP045
    draws: Annotated[int, typer.Option(min=1, help="Seeded draws of the typical world per scene.")] = 1,
    count: Annotated[int, typer.Option(min=1, help="Scripted contacts of each kind per draw.")] = 20,
    scene: Annotated[Optional[list[str]], typer.Option(help="Scene(s) to run (default: every arm scene).")] = None,  # noqa: UP045
    workers: Annotated[Optional[int], typer.Option(min=1, help="Processes (default: one per CPU).")] = None,  # noqa: UP045
    identify_s: Annotated[float, typer.Option(min=0.0, help="s of planned excitation the arm is identified from "
                                                            "first (0: tared only).")] = 60.0,
) -> None:
    """Contact classification (clamping, guidance, impacts) and the events' effective mass on every arm scene,
    typical world."""
    from ftc_hw.bench.classify import SCENES, run  # lazy: CLI start-up

    run(json_path, scenes=tuple(scene) if scene else SCENES, draws=draws, count=count, workers=workers,
        identify_s=identify_s)


@bench_app.command("isolation")
def bench_isolation(
    json_path: Annotated[Optional[Path], typer.Option("--json", help="Write the figures to this JSON file.")] = None,  # noqa: UP045
    cases: Annotated[int, typer.Option(min=50, help="Sampled contacts per scene (two-link ones are kept).")] = 400,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    scene: Annotated[Optional[list[str]], typer.Option(help="Scene(s) to run (default: ur5e, dxl-arm).")] = None,  # noqa: UP045
    reality: Annotated[RealityChoice, reality_option(RealityChoice.typical)] = RealityChoice.typical,
) -> None:
    """Link isolation by motor currents when the force line crosses two links: right, flagged, wrong."""
    from ftc_hw.bench.isolation import run  # lazy: CLI start-up

    run(json_path=json_path, cases=cases, seed=seed, scenes=scene, reality=reality.value)


@bench_app.command("devices")
def bench_devices(
    json_path: Annotated[Optional[Path], typer.Option("--json", help="Write the figures to this JSON file.")] = None,  # noqa: UP045
    duration: Annotated[float, typer.Option(min=1.0, help="Seconds per streaming run.")] = 60.0,
) -> None:
    """F/T adapters against their emulators: rates, loss, corruption, reconnects."""
    from ftc_hw.bench.devices import run  # lazy: CLI start-up

    run(json_path=json_path, duration=duration)


@bench_app.command("arms")
def bench_arms(
    json_path: Annotated[Optional[Path], typer.Option("--json", help="Write the figures to this JSON file.")] = None,  # noqa: UP045
    duration: Annotated[float, typer.Option(min=1.0, help="Seconds per streaming run.")] = 60.0,
    stops: Annotated[int, typer.Option(min=1, help="stop() calls per arm.")] = 200,
) -> None:
    """Arm adapters against their emulators: RTDE rate and accuracy, Dynamixel reads, stop, reconnects."""
    from ftc_hw.bench.arms import run  # lazy: CLI start-up

    run(json_path=json_path, duration=duration, stops=stops)


@bench_app.command("reflex")
def bench_reflex(
    json_path: Annotated[Optional[Path], typer.Option("--json", help="Write the figures to this JSON file.")] = None,  # noqa: UP045
    stops: Annotated[int, typer.Option(min=1, help="Onsets per arm.")] = 200,
) -> None:
    """The stop reflex across the process boundary (the arm's reader in its own process), beside in-process."""
    from ftc_hw.bench.reflex import run  # lazy: CLI start-up

    run(json_path=json_path, stops=stops)


@app.command()
def identify(
    recording: Annotated[Optional[list[Path]], typer.Argument(  # noqa: UP045
        help="Recordings of the arm moving: MCAP (ftc monitor --record), UR recordings (the CSV of UR's RTDE "
             "client or of ur_rtde; with --scene) or ROS 2 bags (with --scene, --topics), one or several.")] = None,
    scene: Annotated[Optional[str], typer.Option(  # noqa: UP045
        help="Built-in scene or scene file (default: the recording's).")] = None,
    sim: Annotated[bool, typer.Option("--sim", help="Record the emulated devices first, then identify.")] = False,
    plan: Annotated[bool, typer.Option("--plan", help="The planned excitation instead of the ordinary sweep: "
                                       "streamed as goals through the arm's protocol where it takes them "
                                       "(DYNAMIXEL; emulated with --sim), else played by the world (--sim).")] = False,
    plan_file: Annotated[Optional[Path], typer.Option(help="Write the planned excitation as CSV (t, q at 125 Hz) "  # noqa: UP045
                                                      "for a controller to play, and exit.")] = None,
    scenario: Annotated[Optional[str], typer.Option(help="With --sim: a contact-free scenario (sweep, excitation, "  # noqa: UP045
                                                    "hold).")] = None,
    duration: Annotated[float, typer.Option(min=5.0, help="Seconds of motion (--sim, --plan, --plan-file).")] = 120.0,
    seed: Annotated[int, typer.Option(help="Random seed (the plan, the simulated world).")] = 0,
    reality: Annotated[RealityChoice, reality_option(RealityChoice.typical, "With --sim: ")] = RealityChoice.typical,
    calibration: Annotated[Optional[Path], typer.Option(help="Start from this calibration (default: --out if it "  # noqa: UP045
                                                        "exists).")] = None,
    out: Annotated[Optional[Path], typer.Option(  # noqa: UP045
        help="Calibration file to write (default calibration-SCENE.toml).")] = None,
    json_path: Annotated[Optional[Path], typer.Option("--json", help="Write the figures as JSON.")] = None,  # noqa: UP045
    keep_contacts: Annotated[bool, typer.Option("--keep-contacts", help="Keep the recording's reported contacts "
                                                "(robust weights instead of cutting them out).")] = False,
    gain: Annotated[bool, typer.Option("--gain/--no-gain", help="Also fit the sensor's linear error on the "
                                       "arm's loads (gain, crosstalk, mount).")] = True,
    plot: Annotated[bool, typer.Option("--plot/--no-plot", help=PLOT_HELP)] = True,
    sensing: SensingOption = None,
    topics: TopicsOption = None,
    device: DeviceOption = None,
    rig: RigOption = None,
) -> None:
    """Identify the arm's inertial parameters and the sensor's errors from free motion, into the calibration."""
    from ftc_hw.app.calibration.identify import IdentifyOptions  # lazy: CLI start-up
    from ftc_hw.cli.identify import run_identify_command  # lazy: CLI start-up

    opts = IdentifyOptions(out=out, calibration=calibration, json_path=json_path, keep_contacts=keep_contacts,
                           gain=gain, plot=plot, topics=topics)
    raise typer.Exit(run_identify_command(recording, scene, sim=sim, plan=plan, plan_file=plan_file,
                                          scenario=scenario, duration=duration, seed=seed, reality=reality.value,
                                          opts=opts, device_overrides=tuple(device or ()), rig=rig,
                                          sensing=sensing))


@app.command()
def serve(
    scene: Annotated[str, typer.Option(help="Built-in scene name or scene file.")],
    device: Annotated[Optional[list[str]], typer.Option(  # noqa: UP045
        "--device", metavar="NAME | NAME.KEY=VALUE", help="A device to serve (repeatable; default: every device "
        "of the scene), or where a device is / one of its params, as for ftc monitor.")] = None,
    rig: RigOption = None,
    listen: Annotated[Optional[list[str]], typer.Option(  # noqa: UP045
        help="Zenoh endpoint to listen on (repeatable; default tcp/127.0.0.1:7447, loopback only).")] = None,
    name: Annotated[Optional[str], typer.Option(  # noqa: UP045
        help="The rig's name in the key expressions ftc/NAME/... (default: the scene's name).")] = None,
    sim: Annotated[bool, typer.Option("--sim", help="Start the scene's world and emulated devices first.")] = False,
    scenario: Annotated[str, typer.Option(help="With --sim: the scenario.")] = "sweep-with-collision",
    seed: Annotated[int, typer.Option(help="With --sim: the world's seed.")] = 0,
    reality: Annotated[RealityChoice, reality_option(RealityChoice.ideal, "With --sim: ")] = RealityChoice.ideal,
    hold: Annotated[float, typer.Option(min=0.0, help="With --sim: seconds at the start pose before the scenario "
                                        "plays (a monitor connecting then tares at rest).")] = 2.0,
    duration: Annotated[Optional[float], typer.Option(  # noqa: UP045
        min=0.1, help="Seconds to serve (with --sim: of the scenario); default until Ctrl-C.")] = None,
    zenoh_config: ZenohConfigOption = None,
) -> None:
    """Each device's reader in its own process, supervised (restarted when it dies), publishing to Zenoh."""
    from ftc_hw.cli.serve import run_serve_command  # lazy: CLI start-up

    raise typer.Exit(run_serve_command(scene, tuple(device or ()), rig, tuple(listen or ()), name, sim, scenario,
                                       seed, reality.value, hold, duration, zenoh_config))


@app.command()
def record(
    remote: Annotated[str, typer.Option(metavar="ENDPOINT", help="The Zenoh endpoint of ftc serve, e.g. "
                                        "tcp/127.0.0.1:7447.")],
    out: Annotated[Path, typer.Option(help="The MCAP file to write.")],
    name: Annotated[str, typer.Option(help="The rig's name in ftc/NAME/... (ftc serve's --name, by default its "
                                      "scene's name).")],
    duration: Annotated[Optional[float], typer.Option(  # noqa: UP045
        min=0.1, help="Seconds to record; default until Ctrl-C.")] = None,
    zenoh_config: ZenohConfigOption = None,
) -> None:
    """Record what ftc serve (and a remote monitor's events) publish on Zenoh, in a process of its own."""
    from ftc_hw.cli.serve import run_record_command  # lazy: CLI start-up

    raise typer.Exit(run_record_command(remote, name, out, duration, zenoh_config))


@app.command()
def calibrate(
    scene: Annotated[str, typer.Option(help="Built-in scene name or scene file.")],
    sim: Annotated[bool, typer.Option("--sim", help="Run against emulated devices (a hidden payload).")] = False,
    sim_payload: Annotated[Optional[str], typer.Option(help="The hidden payload with --sim: mass=KG,com=X,Y,Z "  # noqa: UP045
                                                            "(m, flange frame).")] = None,
    non_interactive: Annotated[bool, typer.Option("--non-interactive", help="No prompts: the same steps.")] = False,
    poses: Annotated[int, typer.Option(min=1, max=200, help="Number of planned poses.")] = 12,
    out: Annotated[Optional[Path], typer.Option(help="Calibration file to write (TOML).")] = None,  # noqa: UP045
    json_path: Annotated[Optional[Path], typer.Option("--json", help="Write the results as JSON.")] = None,  # noqa: UP045
    sample_s: Annotated[float, typer.Option(min=0.05, help="Seconds of F/T samples per pose.")] = 1.0,
    seed: Annotated[int, typer.Option(help="Random seed (planning candidates, simulated noise).")] = 0,
    yaw: Annotated[bool, typer.Option("--yaw", help="Also estimate the sensor's mount rotation about z.")] = False,
    tilt: Annotated[bool, typer.Option("--tilt", help="Also estimate a gravity tilt.")] = False,
    arm_gravity: Annotated[bool, typer.Option("--arm-gravity", help="Also estimate the identifiable corrections "
                                                                  "to the arm's link masses.")] = False,
    expected_mass: Annotated[float, typer.Option(min=0.0, help="Payload mass (kg) the plan's expected "
                                                               "accuracy assumes.")] = 0.5,
    speed: Annotated[float, typer.Option(min=0.05, max=3.0, help="Peak joint speed of the moves, rad/s.")] = 1.0,
    plot: Annotated[bool, typer.Option("--plot/--no-plot", help=PLOT_HELP)] = True,
    device: DeviceOption = None,
    rig: RigOption = None,
    reality: Annotated[RealityChoice, reality_option(RealityChoice.ideal, "With --sim: ")] = RealityChoice.ideal,
) -> None:
    """Calibrate the sensor bias and the payload from planned poses: the bench wizard."""
    from ftc_hw.app.calibration.calibrate import CalibrateOptions, run_calibrate  # lazy: CLI start-up
    from ftc_hw.calibration import FitOptions  # lazy: CLI start-up

    from .calibrate import sim_payload_or_exit  # lazy: CLI start-up
    from .common import scene_or_exit  # lazy: CLI start-up

    spec = scene_or_exit(scene, tuple(device or ()), rig)
    options = CalibrateOptions(sim=sim, sim_payload=sim_payload_or_exit(sim_payload, sim), reality=reality.value,
                               interactive=not non_interactive, poses=poses, sample_s=sample_s, seed=seed,
                               expected_mass=expected_mass, speed=speed,
                               fit=FitOptions(yaw=yaw, tilt=tilt, arm_gravity=arm_gravity), out=out,
                               json_path=json_path, plot=plot)
    raise typer.Exit(run_calibrate(spec, options))


@devices_app.command("probe")
def devices_probe(
    scene: Annotated[Optional[str], typer.Option(  # noqa: UP045
        help="Also try where this scene's devices are (with --device, --rig): their ports, channels, addresses, "
             "ids, baud rates.")] = None,
    port: Annotated[Optional[list[str]], typer.Option(help="A serial port to try (default: the system's serial "  # noqa: UP045
                                                           "ports); repeatable.")] = None,
    can: Annotated[Optional[list[str]], typer.Option(metavar="[INTERFACE:]CHANNEL", help="A CAN channel to ask "  # noqa: UP045
                                                     "for a Net F/T (interface default serial); repeatable.")] = None,
    address: Annotated[Optional[list[str]], typer.Option(help="An IP address to ask for a UR controller and a "  # noqa: UP045
                                                              "Net F/T box (RDT); repeatable.")] = None,
    baud: Annotated[Optional[list[int]], typer.Option(help="A DYNAMIXEL baud rate to try (default: 57600 and "  # noqa: UP045
                                                           "1000000, and the scene's); repeatable.")] = None,
    timeout: Annotated[float, typer.Option(min=0.05, max=5.0, help="Seconds to wait for each answer.")] = 0.3,
    device: DeviceOption = None,
    rig: RigOption = None,
) -> None:
    """List what answers: FT 300s and DYNAMIXEL servos on serial ports, Net F/Ts on CAN or Ethernet, UR controllers."""
    from ftc_hw.cli.devices import run_probe_command  # lazy: CLI start-up

    raise typer.Exit(run_probe_command(scene, tuple(device or ()), rig, ports=port or [], can=can or [],
                                       addresses=address or [], bauds=baud or [], timeout=timeout))


@ros_app.command("publish")
def ros_publish(
    scene: Annotated[str, typer.Option(help="Built-in scene name or scene file.")],
    sim: Annotated[bool, typer.Option("--sim", help="Read the scene's emulated devices in a simulated world (else "
                                                    "the devices where the scene, --rig, --device say).")] = False,
    scenario: Annotated[str, typer.Option(help="With --sim: the scenario (ftc sim --list).")] = "static-pokes",
    duration: Annotated[float, typer.Option(min=0.0, help="With --sim: simulated seconds of the scenario; else "
                                                          "seconds to publish (0: until Ctrl-C).")] = 10.0,
    seed: Annotated[int, typer.Option(help="With --sim: random seed.")] = 0,
    reality: Annotated[RealityChoice, reality_option(RealityChoice.typical, "With --sim: ")] = RealityChoice.typical,
    hold: Annotated[float, typer.Option(min=0.0, help="With --sim: seconds the world holds its start pose once "
                                                      "every topic has a subscriber (a monitor tares its "
                                                      "sensor on the still arm), before the scenario.")] = 1.0,
    truth: Annotated[Optional[Path], typer.Option(help="With --sim: write the world's ground truth (JSON "  # noqa: UP045
                                                       "lines).")] = None,
    joints_topic: Annotated[Optional[str], typer.Option(help="The JointState topic (default the arm's driver's: "  # noqa: UP045
                                                             "/joint_states, /franka/joint_states).")] = None,
    wrench_topic: Annotated[Optional[str], typer.Option(help="The WrenchStamped topic (default "  # noqa: UP045
                                                             "/force_torque_sensor_broadcaster/wrench).")] = None,
    frame_id: Annotated[Optional[str], typer.Option(help="The wrench's header.frame_id (default tool0_controller "  # noqa: UP045
                                                         "for a UR's own sensor, else the scene's sensor "
                                                         "site).")] = None,
    joint_prefix: Annotated[Optional[str], typer.Option(help="Prefixed to the scene's joint names (default "  # noqa: UP045
                                                           "fr3_ or panda_ for a Franka, else none).")] = None,
    stop_service: Annotated[Optional[str], typer.Option(help="Serve a std_srvs/Trigger that stops the arm (default "  # noqa: UP045
                                                            "/dashboard_client/stop for a UR, as ur_robot_driver "
                                                            "does, else none; '' for none).")] = None,
    device: DeviceOption = None,
    rig: RigOption = None,
) -> None:
    """Publish a scene's arm (sensor_msgs/JointState) and F/T sensor (geometry_msgs/WrenchStamped) on ROS 2 as
    their vendors' drivers do, read through ftc's adapters: from emulators with --sim, else from the devices."""
    from ftc_hw.cli.ros import run_publish_command  # lazy: CLI start-up

    raise typer.Exit(run_publish_command(
        scene=scene, devices=tuple(device or ()), rig=rig, sim=sim, scenario=scenario, reality=reality.value, seed=seed,
        duration=duration, hold_s=hold, joints_topic=joints_topic, wrench_topic=wrench_topic, frame_id=frame_id,
        joint_prefix=joint_prefix, stop_service=stop_service, truth=truth))


@app.command(hidden=True)
def warm(
    scene: Annotated[Optional[list[str]], typer.Option(help="Scenes whose kernels to load (default: the "  # noqa: UP045
                                                            "built-in ones).")] = None,
) -> None:
    """Compile the numba kernels of ftc demo and ftc monitor --sim into numba's cache (scripts/bootstrap.sh runs it)."""
    typer.echo("[warm] loading MuJoCo and numba ...", err=True)
    from ftc_hw.app.setup.warm import warm as run_warm  # lazy: CLI start-up

    from .common import scene_or_exit  # lazy: CLI start-up

    run_warm([scene_or_exit(name) for name in scene] if scene else None)


def run() -> None:
    """The ``ftc`` command (its console script and ``python -m ftc_hw``): the app, then the process ends as
    soon as it is done (:func:`end_process`)."""
    try:
        app(prog_name="ftc")
    except SystemExit as exc:
        end_process(exc.code)
    end_process(0)

