"""``ftc bench provisional``: the provisional onset (docs/monitor.md) over long simulated runs, offline, on the
monitor's own code, with the joint stream's arrival pattern of a real-time run.

The drawn world's devices are simulated ahead (the F/T samples at the sensor's rate, the joint samples at the
arm's, with the world's truth), then delivered to a :class:`~ftc_hw.monitor.LiveMonitor` in order of their
arrival on a simulated clock: each sample arrives its sample time plus a delivery delay, and joint samples are
missed, both as a recording of a real-time run (``ftc monitor --record``) measured them, taken in turn (or,
without one, the delays measured on this host: ``DEFAULT_*`` below). The monitor takes each F/T frame as its
worker does (:meth:`~ftc_hw.monitor.LiveMonitor.take`: judged provisionally at once) and judges the frames
whose joint state is there (:meth:`~ftc_hw.monitor.LiveMonitor.judge_ready`) at each arrival.

Figures: provisional onsets and confirmed ones against the truth (false alarms: an onset with no contact from
``EARLY_S`` before it to ``LATE_S`` after a contact's end), provisional onsets not confirmed, contacts whose
first onset was provisional, and the decision's delay: from the onset sample's time to the arrival of the frame
whose judgement made the onset (the stop is sent then, plus the monitor's compute time, which this does not
measure: the real-time run does). Not simulated: the arm's reaction to a stop (the world is computed ahead: the
sweep goes on through each contact), so the stops' and resumptions' transients are the real-time run's to show.
"""
from __future__ import annotations

import dataclasses
import json
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rich.table import Table

from ftc_hw.app.calibration.identify import identify
from ftc_hw.bench.compensation import arm_rate
from ftc_hw.bench.compensation import record as record_excitation
from ftc_hw.bench.report import table_console
from ftc_hw.bus import EVENTS_CONTACT, EVENTS_DEVICE, Bus, ClockAligner, JointFrame, WrenchFlag, WrenchFrame
from ftc_hw.calibration.free_motion import MotionData
from ftc_hw.model import ArmModel
from ftc_hw.monitor import LiveMonitor
from ftc_hw.pipeline import Corrections, LocalizationSettings, MotionSettings, PipelineSettings
from ftc_hw.record.reader import read_recording
from ftc_hw.scene import Scene, load_scene
from ftc_hw.sim_devices.world import World, with_reality
from ftc_hw.sim_devices.world.scenarios import SCENARIOS

EARLY_S, LATE_S = 0.005, 0.3  # an onset this close to a contact (before its start, after its end) is not false
# ESTIMATE: delivery delays without a recording, from `ftc monitor --sim` runs on this host (docs/measurements/
# monitor.md): RTDE packets 0.2-1 ms after their sample, 0.85 % missed; CAN F/T frames 0.1-0.3 ms
DEFAULT_JOINT_DELAY_S = (0.0002, 0.001)
DEFAULT_JOINT_MISSED = 0.0085
DEFAULT_FT_DELAY_S = (0.0001, 0.0003)


@dataclass
class Streams:
    """What the devices deliver: F/T samples (times ns, (N, 6) readings, saturation) with the truth (in contact),
    joint samples (times ns, (M, n) q, qd, current)."""

    ft_t: np.ndarray
    wrench: np.ndarray
    saturated: np.ndarray
    contact: np.ndarray
    joint_t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    current: np.ndarray


@dataclass
class Arrivals:
    """Delivery delays ns (taken in turn) of joint and F/T samples, and which joint samples are missed (in turn)."""

    joint_delay_ns: np.ndarray
    joint_missed: np.ndarray
    ft_delay_ns: np.ndarray
    source: str


def simulate(scene: Scene, world_scene: Scene, scenario: str, duration: float, seed: int) -> Streams:
    """``duration`` s of ``scenario`` in the world of ``world_scene``: the devices' samples, at their rates."""
    rng = np.random.default_rng(seed)
    params = {"speed": 1.0} if scenario.startswith("sweep") else {}
    setup = SCENARIOS[scenario].build(scene, ArmModel(scene), rng, duration, **params)
    world = World(world_scene, setup, seed=seed)
    joint_every = max(1, round(1.0 / (arm_rate(scene) * world.dt)))
    ft, joints = [], []
    for _ in range(int(round(duration / world.dt))):
        s = world.step()
        if world.steps % joint_every == 0:
            joints.append((s.t, s.q, s.qd, world.read_current(s)))
        if world.steps % world.steps_per_sample == 0:
            r = world.read_sensor(s)
            ft.append((s.t, r.wrench, bool(r.saturated.any()), bool(s.contacts)))
    ns = lambda xs: np.array([round(x * 1e9) for x in xs], dtype=np.int64)  # noqa: E731
    return Streams(ns([f[0] for f in ft]), np.array([f[1] for f in ft]), np.array([f[2] for f in ft]),
                   np.array([f[3] for f in ft]), ns([j[0] for j in joints]), np.array([j[1] for j in joints]),
                   np.array([j[2] for j in joints]), np.array([j[3] for j in joints]))


def default_arrivals(seed: int, n: int = 100_000) -> Arrivals:
    rng = np.random.default_rng(seed)
    return Arrivals((rng.uniform(*DEFAULT_JOINT_DELAY_S, n) * 1e9).astype(np.int64),
                    rng.random(n) < DEFAULT_JOINT_MISSED,
                    (rng.uniform(*DEFAULT_FT_DELAY_S, n) * 1e9).astype(np.int64), "ESTIMATE (no recording)")


def arrivals_from_recording(path: Path, seed: int = 0, joint_topic: str = "joints/arm") -> Arrivals:
    """The joint stream's delays (receive time less the device time aligned by the minimum-delay filter, shifted
    so the least is 0) and missed samples (the device clock's spacing over 1.5 periods) of a recording; the F/T
    frames' delays the estimate's (a recording's F/T delays on a host that fell behind are its backlog, seconds,
    through a clock alignment capped at 1 ms/s: not a delivery pattern)."""
    rec = read_recording(path, topics={joint_topic})

    def delays(frames: list) -> np.ndarray:
        clock = ClockAligner()
        d = []
        for f in frames:
            clock.update(f.t_device_ns, f.t_host_ns)
            d.append(f.t_host_ns - clock.to_host(f.t_device_ns))
        d = np.array(d[len(d) // 20:], dtype=np.int64)  # the filter's first estimates left out
        return d - d.min()

    joints = [f for f in rec.topic(joint_topic) if f.t_device_ns is not None]
    t = np.array([f.t_device_ns for f in joints], dtype=np.int64)
    period = np.median(np.diff(t))
    missed = []
    for gap in np.diff(t):
        k = int(round(gap / period))
        missed += [True] * max(k - 1, 0) + [False]
    ft = default_arrivals(seed).ft_delay_ns
    return Arrivals(delays(joints), np.array(missed), ft, f"joints: {path}; F/T: ESTIMATE")


def corrections_for(scene: Scene, world_scene: Scene, identify_s: float, seed: int) -> Corrections:
    """The drawn arm identified from ``identify_s`` s of planned excitation (``ftc identify --plan``'s fit), tared
    at rest like the monitor (the bias left out); none in the ideal world (``identify_s`` 0)."""
    if identify_s <= 0:
        return Corrections()
    train = record_excitation(scene, "excitation", identify_s, 1.0, 1000 + seed, world_scene)
    cal, _ = identify(scene, [MotionData(train.t, train.wrench, train.q, train.qd, train.current)], None,
                      "bench provisional: excitation")
    return dataclasses.replace(cal.corrections(scene), bias=None)


def deliver(scene: Scene, streams: Streams, arrivals: Arrivals, settings: PipelineSettings) -> dict[str, Any]:
    """The streams through a monitor in order of arrival (module docstring); the events with their decision times."""
    monitor = LiveMonitor(Bus(), scene, settings=settings, tare_s=0.1, publish_inputs=False)
    now = [0]
    seen: list[tuple[str, int, int]] = []  # (kind, onset t ns, decided at ns)

    def note(ev) -> None:
        if ev.kind in ("onset", "provisional_onset", "provisional_unconfirmed"):
            seen.append((ev.kind, ev.t_host_ns, now[0]))

    monitor.bus.subscribe(EVENTS_CONTACT, callback=note)
    monitor.bus.subscribe(EVENTS_DEVICE, callback=note)
    order = _arrival_order(streams, arrivals)
    pending: deque = deque()
    for at, kind, i in order:
        now[0] = at
        if kind == 0:
            monitor.on_joints(JointFrame.make(at, streams.q[i], streams.qd[i], streams.current[i], source="arm",
                                              seq=i, t_device_ns=int(streams.joint_t[i])))
        else:
            flags = WrenchFlag.SATURATED if streams.saturated[i] else WrenchFlag.NONE
            monitor.take(pending, [WrenchFrame.make(at, streams.wrench[i], source="ft", seq=i,
                                                    t_device_ns=int(streams.ft_t[i]), flags=flags)], at * 1e-9)
        monitor.judge_ready(pending, at * 1e-9)
    now[0] = order[-1][0] + 10**9
    monitor.judge_ready(pending, now[0] * 1e-9)
    return {"events": seen, "counters": dict(monitor.counters), "offset_ns": _offset(streams, arrivals)}


def _arrival_order(streams: Streams, arrivals: Arrivals) -> list[tuple[int, int, int]]:
    """(arrival ns, 0 joint | 1 F/T, index) in order of arrival; missed joint samples left out."""
    jd, jm, fd = arrivals.joint_delay_ns, arrivals.joint_missed, arrivals.ft_delay_ns
    out = [(int(t + jd[i % jd.size]), 0, i) for i, t in enumerate(streams.joint_t) if not jm[i % jm.size]]
    out += [(int(t + fd[i % fd.size]), 1, i) for i, t in enumerate(streams.ft_t)]
    out.sort()
    return out


def _offset(streams: Streams, arrivals: Arrivals) -> int:
    """The aligned clock's offset from the device's: the least F/T delay (the minimum-delay filter's)."""
    return int(arrivals.ft_delay_ns.min())


def judge(streams: Streams, delivered: dict[str, Any]) -> dict[str, Any]:
    """The events against the truth (module docstring)."""
    t = streams.ft_t
    episodes = _episodes(t, streams.contact)
    off = delivered["offset_ns"]
    prov = [(t0 - off, d) for k, t0, d in delivered["events"] if k == "provisional_onset"]
    conf = [(t0 - off, d) for k, t0, d in delivered["events"] if k == "onset"]
    false_prov = [x for x in prov if not _near(x[0], episodes)]
    false_conf = [x for x in conf if not _near(x[0], episodes)]
    first, delays = 0, []
    for a, b in episodes:
        cands = [(d, "p", t0) for t0, d in prov if a - EARLY_S * 1e9 <= t0 <= b] + \
                [(d, "c", t0) for t0, d in conf if a - EARLY_S * 1e9 <= t0 <= b]
        if cands:
            d, who, t0 = min(cands)
            first += who == "p"
            delays.append((d - t0 - off) / 1e6)
    c = delivered["counters"]
    return {"simulated_s": float((t[-1] - t[0]) * 1e-9), "contacts": len(episodes),
            "detected": len(delays), "first_provisional": first,
            "provisional_onsets": len(prov), "confirmed_onsets": len(conf),
            "false_provisional": len(false_prov), "false_confirmed": len(false_conf),
            "provisional_unconfirmed": int(c.get("provisional_unconfirmed", 0)),
            "decision_ms_median": float(np.median(delays)) if delays else float("nan"),
            "decision_ms_p99": float(np.percentile(delays, 99)) if delays else float("nan"),
            "decision_ms_max": float(np.max(delays)) if delays else float("nan"),
            "false_provisional_t_s": [round(x[0] * 1e-9, 4) for x in false_prov],
            "counters": {k: v for k, v in c.items() if "provisional" in k or k in ("frames", "errors")}}


def _episodes(t: np.ndarray, contact: np.ndarray) -> list[tuple[int, int]]:
    edges = np.flatnonzero(np.diff(np.r_[0, contact.astype(int), 0]))
    return [(int(t[a]), int(t[b - 1])) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def _near(t0: int, episodes: list[tuple[int, int]]) -> bool:
    return any(a - EARLY_S * 1e9 <= t0 <= b + LATE_S * 1e9 for a, b in episodes)


def chunk_arrivals(base: Arrivals | None, seed: int, k: int) -> Arrivals:
    """The ``k``-th chunk's arrivals: a recording's taken from another place in turn, or drawn anew."""
    if base is None:
        return default_arrivals(seed + k)
    shift = 7919 * k  # a splice of the delays: a few frames there arrive out of their order, as none do live
    return Arrivals(np.roll(base.joint_delay_ns, shift), np.roll(base.joint_missed, shift),
                    np.roll(base.ft_delay_ns, shift), base.source)


def run(scene_name: str = "ur5e", *, reality: str = "typical", minutes: float = 10.0, seed: int = 0,
        identify_s: float = 60.0, recording: Path | None = None, chunk_s: float = 60.0,
        json_path: Path | None = None) -> dict[str, Any]:
    """``minutes`` of the collision sweep in ``chunk_s`` runs (noise seeds ``seed + 100``, ...) of one drawn world
    (``seed``), identified first from ``identify_s`` s of excitation (not in the ideal world); a table and JSON."""
    scene = load_scene(scene_name)
    world_scene = with_reality(scene, reality, seed=seed)
    corrections = corrections_for(scene, world_scene, identify_s if reality != "ideal" else 0.0, seed)
    settings = PipelineSettings(corrections=corrections, motion=MotionSettings(level="dynamics"),
                                localization=LocalizationSettings(surface="primitives"))
    base = arrivals_from_recording(recording) if recording else None
    chunks = []
    for k in range(max(1, round(minutes * 60 / chunk_s))):
        streams = simulate(scene, world_scene, "sweep-with-collision", chunk_s, seed + 100 + k)
        chunks.append(judge(streams, deliver(scene, streams, chunk_arrivals(base, seed, k), settings)))
    out = {"scene": scene_name, "reality": reality, "seed": seed,
           "arrivals": base.source if base is not None else "ESTIMATE (no recording)", "chunks": chunks}
    _table(out)
    if json_path is not None:
        json_path.write_text(json.dumps(out, indent=1))
    return out


def _table(out: dict[str, Any]) -> None:
    chunks = out["chunks"]
    total = lambda key: sum(c[key] for c in chunks)  # noqa: E731
    table = Table(title=f"provisional onset: {out['scene']}, {out['reality']} world, arrivals {out['arrivals']}")
    for name in ("simulated min", "contacts", "detected", "first provisional", "false provisional",
                 "false confirmed", "unconfirmed", "decision ms median / p99 / max"):
        table.add_column(name, justify="right")
    table.add_row(f"{sum(c['simulated_s'] for c in chunks) / 60:.1f}", str(total("contacts")), str(total("detected")),
                  str(total("first_provisional")), str(total("false_provisional")), str(total("false_confirmed")),
                  str(total("provisional_unconfirmed")),
                  " / ".join(f"{max(c[k] for c in chunks):.2f}" for k in ("decision_ms_median", "decision_ms_p99",
                                                                         "decision_ms_max")))
    table_console().print(table)
