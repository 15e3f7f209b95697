"""The real-time leg of ``ftc bench pipeline``: ``ftc monitor --scene S --sim --world-ahead --duration D --reflex
stop --resume-after 0.5 --record F --truth T`` (readers in threads, no live view), and what it kept up with
(:class:`~ftc_hw.bench.pipeline.RealtimeLeg`: its world and calibration). With the world computed ahead (the
default; ``ahead=False``: the live world) the emulators serve the stored run and the simulated cell costs only
their sockets; a stop changes nothing in the played run (it goes on through each contact). The emulated UR
controller's operator plays again half a second after each stop, so every contact of the sweep meets a stop (a
UR arm's scenes; with another arm in the live world the sweep stops at its first contact). With ``split_cores``
the cell's processes (the world, the emulators) run on one core and the monitor with its threads and recorder on
the others (:mod:`.cores`): a real cell's monitor host runs no simulator.

Figures: the F/T adapter's counters (for RDT ``box_packets``, the box's own count of what it sent, against
``packets`` received and ``kernel_drops``, the socket's overflows; for every kind ``lost``, the samples its
sequence says are missing), the monitor's frames judged and not judged (dropped behind its queue, no joint
state, unjudged at the end), contacts detected and false alarms against the world's truth, onset delay (from
the first contact sample's publication; computed ahead: from when it was due), the stop reflex's latency (sent
after the onset's time) and, per contact, the stop command's arrival at the arm's interface (the UR emulator
read it) after the contact's first sample, and each process's CPU share over the scenario (:mod:`.process_cpu`:
this one, the monitor with its readers and pipeline; the world's, the emulators', the recorder's; the host's
busy cores). The recording, afterwards: its messages against what the monitor judged, the recorder's drops, and
a replay of it (``ftc replay --check``): whether it gives the run's events bit for bit."""
from __future__ import annotations

import contextlib
import io
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console

from ftc_hw.app.monitor.config import DeviceOptions, MonitorOptions, SimOptions, ViewOptions
from ftc_hw.app.monitor.evaluate import _episodes
from ftc_hw.app.monitor.session import resumable, run_monitor
from ftc_hw.bench.cores import Pinned, core_split
from ftc_hw.bench.pipeline import RealtimeLeg
from ftc_hw.bench.process_cpu import SELF, ProcessCpu
from ftc_hw.bus import EVENTS_DEVICE
from ftc_hw.monitor import MONITOR_INPUT
from ftc_hw.record.events import read_truth
from ftc_hw.record.reader import Recording, read_recording
from ftc_hw.record.replay import replay
from ftc_hw.scene import load_scene

RESUME_AFTER_S = 0.5
MERGE_GAP_S = 0.05  # contact runs closer than this are one contact (the evaluation's default)
LATE_NS = 50_000_000  # a stop this long after a contact's end is still its (the evaluation's onset window)

NOT_JUDGED = ("ft_frames_dropped", "no_joint_state", "blind_frames", "ft_frames_unjudged_at_stop")


def live(scene: str, leg: RealtimeLeg, seed: int) -> dict[str, Any]:
    """One real-time run of ``scene`` and its figures (module docstring)."""
    ur = resumable(load_scene(scene))
    with tempfile.TemporaryDirectory(prefix="ftc-bench-") as tmp:
        path, truth = Path(tmp) / "run.mcap", Path(tmp) / "truth.jsonl"
        world = SimOptions(seed=seed, reality=leg.reality, resume_after_s=RESUME_AFTER_S if ur else None, truth=truth,
                           ahead=leg.ahead)
        cfg = MonitorOptions(scene, sim=True, world=world, duration=leg.seconds, view=ViewOptions("none"),
                             reflex="stop", devices=DeviceOptions(readers="thread"), title="ftc bench pipeline",
                             record=path, calibration=leg.calibration)
        load = os.getloadavg()[0]
        split = core_split() if leg.split_cores else None
        with ProcessCpu() as cpu, Pinned(split) if split else contextlib.nullcontext():
            out = run_monitor(cfg, Console(file=io.StringIO(), width=200))
        rows = read_truth(truth) if truth.exists() else []
        rec = read_recording(path)
        return {**_figures(scene, leg.seconds, load, out), "world": "ahead" if leg.ahead else "live",
                "reality": leg.reality, "calibration": str(leg.calibration) if leg.calibration else None,
                "cores": {"cell": sorted(split.cell), "monitor": sorted(split.monitor)} if split else "shared",
                **_cpu(cpu, rows), **_stops_at_arm(rows, out.reflex.get("stops_at_arm_ns", [])),
                **_replayed(rec), **_after_arrival(rec, out.reflex.get("stops", []))}


def _cpu(cpu: ProcessCpu, truth: list[dict[str, Any]]) -> dict[str, Any]:
    """Each process's CPU share over the scenario (from its first truth sample's host time to its last)."""
    if not truth:
        return {"cpu_share": float("nan"), "cpu_by_process": {}}
    shares = cpu.shares(int(truth[0]["t_host_ns"]), int(truth[-1]["t_host_ns"]))
    return {"cpu_share": shares.get(SELF, float("nan")), "cpu_by_process": shares}


def _stops_at_arm(truth: list[dict[str, Any]], stops_ns: list[int]) -> dict[str, Any]:
    """Per true contact (runs of contact samples, as the evaluation merges them), ms from its first sample's
    host time to the first stop command the arm's emulator read after it (its ``t_rx_ns``): the reflex at the
    arm's interface, whatever the world then does."""
    th = np.array([r["t_host_ns"] for r in truth], dtype=np.int64)
    ts = np.array([r["t"] for r in truth], dtype=float)
    stops = np.sort(np.array(stops_ns, dtype=np.int64))
    ms = []
    for a, b in _episodes(ts, np.array([bool(r["contact"]) for r in truth]), MERGE_GAP_S) if len(truth) else []:
        later = stops[(stops >= th[a]) & (stops <= th[b] + LATE_NS)]
        if later.size:
            ms.append((int(later[0]) - int(th[a])) / 1e6)
    return {"stops_at_arm": len(ms), **_spread("stop_at_arm_ms", ms)}


def _replayed(rec: Recording) -> dict[str, Any]:
    """The recording against the run: inputs recorded and judged, and its replay's events."""
    result = replay(rec)
    recorder = rec.metadata.get("recorder", {})
    return {"recorded_inputs": sum(m.topic == MONITOR_INPUT for m in rec.messages),
            "recorder_drops": int(recorder.get("drops", -1)), "recording_complete": rec.complete,
            "replayed_events": len(result.events), "replay_identical": result.identical}


def _figures(scene: str, seconds: float, load: float, out) -> dict[str, Any]:
    c = out.counters
    ft = next((v for v in out.device_counters.values() if "records" in v or "frames" in v), {})
    judged = int(c.get("frames", 0))
    not_judged = int(sum(c.get(k, 0) for k in NOT_JUDGED))
    ev = out.evaluation
    delays = [x.onset_delay_ms for x in ev.contacts if x.onset_delay_ms is not None] if ev else []
    stops = [s["sent_after_onset_ms"] for s in out.reflex.get("stops", [])]
    return {
        "scene": scene, "seconds": seconds, "load_1min": load, "exit_code": out.exit_code,
        "sent": ft.get("box_packets"), "received": ft.get("packets", ft.get("frames")),
        "kernel_drops": ft.get("kernel_drops", 0), "seq_lost": ft.get("lost", 0),
        "judged": judged, "not_judged": not_judged,
        "not_judged_share": not_judged / (judged + not_judged) if judged + not_judged else float("nan"),
        "backlog_frames": int(c.get("ft_frames_backlog", 0)), "judge_lag_ms_p99": c.get("judge_lag_ms_p99"),
        "arm_missed": sum(v.get("missed_packets", 0) for v in out.device_counters.values()),
        "evaluated": ev is not None, "contacts": len(ev.contacts) if ev else 0, "detected": ev.detected if ev else 0,
        "false_alarms": len(ev.false_alarms) if ev else 0, "false_alarm_s": list(ev.false_alarms) if ev else [],
        "onset_delay_ms_median": float(np.median(delays)) if delays else float("nan"),
        **_spread("stop_after_onset_ms", stops), "stops": len(stops),
        # the provisional onset (docs/monitor.md): stops sent on one, and those the pipeline did not confirm
        "stops_provisional": sum(bool(s.get("provisional")) for s in out.reflex.get("stops", [])),
        "provisional_onsets": int(c.get("provisional_onsets", 0)),
        "provisional_unconfirmed": int(c.get("provisional_unconfirmed", 0)),
        "onsets_without_provisional": int(c.get("onsets_without_provisional", 0)),
        "reflex_errors": list(out.reflex.get("errors", [])),
        "degraded": list(out.degraded), "problems": list(out.problems), "device_counters": out.device_counters,
    }


def _after_arrival(rec: Recording, stops: list[dict[str, Any]]) -> dict[str, Any]:
    """Per stop on a provisional onset, ms from the arrival of the F/T frame that decided it (the onset's
    ``frame_received_ns``, in the recording) to the stop command's sending: the monitor's own share of the
    stop's latency, without the emulated device's delivery and the detector's debounce (``n_on`` periods)."""
    received = {m.frame.t_host_ns: m.frame.counters.get("frame_received_ns") for m in rec.messages
                if m.topic == EVENTS_DEVICE and getattr(m.frame, "kind", "") == "provisional_onset"}
    ms = [s["sent_after_onset_ms"] - (received[s["onset_t_host_ns"]] - s["onset_t_host_ns"]) / 1e6
          for s in stops if s.get("provisional") and received.get(s["onset_t_host_ns"]) is not None]
    return {"stops_timed_from_arrival": len(ms), **_spread("stop_after_arrival_ms", ms)}


def _spread(prefix: str, ms: list[float]) -> dict[str, float]:
    """``{prefix}_median``, ``_p99`` and ``_max`` of ``ms`` (NaN when there are none)."""
    nan = float("nan")
    return {f"{prefix}_median": float(np.median(ms)) if ms else nan,
            f"{prefix}_p99": float(np.percentile(ms, 99)) if ms else nan,
            f"{prefix}_max": float(np.max(ms)) if ms else nan}
