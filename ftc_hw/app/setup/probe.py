"""``ftc devices probe``: what to try -- the serial ports, CAN channels and addresses given, a scene's
devices where its file, a rig file or ``--device`` options say they are, else the system's serial
ports -- the probes themselves (:mod:`ftc_hw.devices.probe`), and the report: what answered, with its
identity, and every candidate tried with what came back."""
from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

from rich.console import Console
from rich.table import Table

from ftc_hw.devices.probe import (
    DXL_BAUDS,
    Finding,
    probe_dynamixel,
    probe_ft300,
    probe_netft,
    probe_netft_rdt,
    probe_ur,
    serial_ports,
)
from ftc_hw.scene import Scene
from ftc_hw.scene.device_params import located, locator_key


@dataclass(frozen=True)
class Candidate:
    """One thing to try: ``kind`` ft300 | dynamixel | can | rdt | ur at ``where``, with its probe's options."""

    kind: str
    where: str
    options: tuple[tuple[str, Any], ...] = ()


@dataclass
class ProbePlan:
    candidates: list[Candidate] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)  # scene devices not probed, and why

    def add(self, kind: str, where: str, **options: Any) -> None:
        c = Candidate(kind, where, tuple(sorted(options.items())))
        if all((x.kind, x.where) != (kind, where) for x in self.candidates):
            self.candidates.append(c)


def plan_probe(scene: Scene | None = None, *, ports: Sequence[str] = (), can: Sequence[str] = (),
               addresses: Sequence[str] = (), bauds: Sequence[int] = ()) -> ProbePlan:
    """The candidates: a scene's located devices, then every port (an FT 300 and DYNAMIXEL servos
    each), CAN channel (``[interface:]channel``) and address (a UR controller and a Net F/T box) given;
    the system's serial ports when nothing else is."""
    plan = ProbePlan()
    bauds = tuple(bauds) or DXL_BAUDS
    if scene is not None:
        _plan_scene(plan, scene, bauds)
    if not (scene or ports or can or addresses):
        ports = serial_ports()
        plan.notes.append(f"the system's serial ports: {', '.join(ports) or 'none'}")
    for port in ports:
        plan.add("ft300", port)
        plan.add("dynamixel", port, bauds=bauds)
    for text in can:
        interface, sep, channel = text.partition(":")
        if sep and "/" not in interface:
            plan.add("can", channel, interface=interface)
        else:
            plan.add("can", text)
    for address in addresses:
        plan.add("ur", address)
        plan.add("rdt", address)
    return plan


def _plan_scene(plan: ProbePlan, scene: Scene, bauds: tuple[int, ...]) -> None:
    for d in scene.devices:
        p = d.params
        if not located(d.kind, d.address, p):
            plan.notes.append(f"{d.name} ({d.kind}): no address, not probed (--device "
                              f"{d.name}.{locator_key(d.kind)}=...)")
        elif d.kind == "ft300" and d.transport == "modbus-rtu":
            plan.add("ft300", d.address, baudrate=p.get("baudrate", 19200), device_id=p.get("device_id", 9))
        elif d.kind == "dynamixel":
            plan.add("dynamixel", d.address, bauds=tuple(dict.fromkeys((p.get("baudrate", 1_000_000), *bauds))))
        elif d.kind == "ft-can":
            plan.add("can", p.get("channel") or d.address, interface=p.get("interface", "serial"),
                     base_id=p.get("base_id", 8), dbc=p.get("dbc", "ati_netft_can.dbc"))
        elif d.kind == "ft-rdt":
            plan.add("rdt", d.address, port=p.get("port", 49152), http_port=p.get("http_port", 80))
        elif d.kind == "ur-rtde":
            plan.add("ur", d.address, dashboard_port=p.get("dashboard_port", 29999))
        else:
            plan.notes.append(f"{d.name} ({d.kind} over {d.transport}): no probe for this kind")


def probe(plan: ProbePlan, timeout: float = 0.3) -> tuple[list[Finding], list[str]]:
    """Every candidate, in order: (what answered, what was tried and what came back)."""
    found: list[Finding] = []
    tried: list[str] = []
    for c in plan.candidates:
        opts = dict(c.options)
        if c.kind == "dynamixel":
            finds, notes = probe_dynamixel(c.where, opts.get("bauds", DXL_BAUDS))
            found += finds
            tried += notes
            continue
        if c.kind == "ft300":
            finding, note = probe_ft300(c.where, timeout=timeout, **opts)
        elif c.kind == "can":
            finding, note = probe_netft(c.where, timeout=timeout, **opts)
        elif c.kind == "rdt":
            finding, note = probe_netft_rdt(c.where, timeout=timeout, **opts)
        else:
            finding, note = probe_ur(c.where, timeout=timeout, **opts)
        tried.append(note)
        if finding is not None:
            found.append(finding)
    return found, tried


def run_probe(plan: ProbePlan, timeout: float, console: Console | None = None) -> int:
    """Probe and print; exit code 0 when something answered, 1 when nothing did."""
    console = console or Console()
    for note in plan.notes:
        console.print(f"note: {note}")
    with console.status(f"probing {len(plan.candidates)} candidates ({timeout:g} s per request)"):
        found, tried = probe(plan, timeout)
    console.print("tried:")
    for line in tried:
        console.print(f"  {line}", highlight=False)
    if not found:
        console.print("nothing answered")
        return 1
    console.print(found_table(found))
    return 0


def found_table(found: Iterable[Finding]) -> Table:
    t = Table(title="answered", title_justify="left")
    for col in ("device", "where", "identity"):
        t.add_column(col)
    for f in found:
        t.add_row(f.what, f.where, ", ".join(f"{k} {_text(v)}" for k, v in f.identity.items()))
    return t


def _text(value: Any) -> str:
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {v}" for k, v in value.items()) + "}"
    if isinstance(value, list | tuple):
        return ",".join(map(str, value))
    return str(value)
