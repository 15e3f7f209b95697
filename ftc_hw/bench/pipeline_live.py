"""The real-time leg of ``ftc bench pipeline``: ``ftc monitor --scene S --sim --duration D --reflex stop
--resume-after 0.5 --record F`` (readers in threads, no live view), and what it kept up with. The
emulated UR controller's operator plays again half a second after each stop, so every contact of the
sweep meets a stop (a UR arm's scenes; with another arm the sweep stops at its first contact).

Figures: the F/T adapter's counters (for RDT ``box_packets``, the box's own count of what it sent,
against ``packets`` received and ``kernel_drops``, the socket's overflows; for every kind ``lost``,
the samples its sequence says are missing), the monitor's frames judged and not judged (dropped behind
its queue, no joint state, unjudged at the end), contacts detected and false alarms against the world's
truth, onset delay (from the first contact sample's publication) and the stop reflex's latency (sent
after the onset's time), and this process's CPU share (readers, monitor, pipeline: the world and the
emulators run in processes of their own) while it streamed. The recording, afterwards: its messages
against what the monitor judged, the recorder's drops, and a replay of it (``ftc replay --check``):
whether it gives the run's events bit for bit.
"""
from __future__ import annotations

import io
import os
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console

from ftc_hw.app.monitor.config import DeviceOptions, MonitorOptions, SimOptions, ViewOptions
from ftc_hw.app.monitor.session import resumable, run_monitor
from ftc_hw.monitor import MONITOR_INPUT
from ftc_hw.record.reader import read_recording
from ftc_hw.record.replay import replay
from ftc_hw.scene import load_scene

RESUME_AFTER_S = 0.5

NOT_JUDGED = ("ft_frames_dropped", "no_joint_state", "blind_frames", "ft_frames_unjudged_at_stop")


class CpuSampler:
    """This process's CPU seconds (user + system) sampled every ``period_s`` in a thread."""

    def __init__(self, period_s: float = 0.25) -> None:
        self.period_s = period_s
        self.samples: list[tuple[float, float]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="bench-cpu", daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            t = os.times()
            self.samples.append((time.monotonic(), t.user + t.system))
            self._stop.wait(self.period_s)

    def __enter__(self) -> CpuSampler:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()

    def busy_share(self, floor: float = 0.05) -> float:
        """CPU seconds per wall second (1.0: one core) from the first to the last sampling interval above
        ``floor`` (the streaming: before it the world starts, after it the run's summary)."""
        busy = [i for i in range(1, len(self.samples)) if _share(self.samples[i - 1], self.samples[i]) > floor]
        if not busy:
            return float("nan")
        return _share(self.samples[busy[0] - 1], self.samples[busy[-1]])


def _share(a: tuple[float, float], b: tuple[float, float]) -> float:
    return (b[1] - a[1]) / (b[0] - a[0]) if b[0] > a[0] else 0.0


def live(scene: str, seconds: float, seed: int) -> dict[str, Any]:
    ur = resumable(load_scene(scene))
    with tempfile.TemporaryDirectory(prefix="ftc-bench-") as tmp:
        path = Path(tmp) / "run.mcap"
        world = SimOptions(seed=seed, resume_after_s=RESUME_AFTER_S if ur else None)
        cfg = MonitorOptions(scene, sim=True, world=world, duration=seconds, view=ViewOptions("none"), reflex="stop",
                             devices=DeviceOptions(readers="thread"), title="ftc bench pipeline", record=path)
        load = os.getloadavg()[0]
        with CpuSampler() as cpu:
            out = run_monitor(cfg, Console(file=io.StringIO(), width=200))
        return {**_figures(scene, seconds, load, out, cpu), **_replayed(path)}


def _replayed(path: Path) -> dict[str, Any]:
    """The recording against the run: inputs recorded and judged, and its replay's events."""
    rec = read_recording(path)
    result = replay(rec)
    recorder = rec.metadata.get("recorder", {})
    return {"recorded_inputs": sum(m.topic == MONITOR_INPUT for m in rec.messages),
            "recorder_drops": int(recorder.get("drops", -1)), "recording_complete": rec.complete,
            "replayed_events": len(result.events), "replay_identical": result.identical}


def _figures(scene: str, seconds: float, load: float, out, cpu: CpuSampler) -> dict[str, Any]:
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
        "false_alarms": len(ev.false_alarms) if ev else 0,
        "onset_delay_ms_median": float(np.median(delays)) if delays else float("nan"),
        "stop_after_onset_ms_median": float(np.median(stops)) if stops else float("nan"),
        "stop_after_onset_ms_p99": float(np.percentile(stops, 99)) if stops else float("nan"),
        "stop_after_onset_ms_max": float(np.max(stops)) if stops else float("nan"), "stops": len(stops),
        # the provisional onset (docs/monitor.md): stops sent on one, and those the pipeline did not confirm
        "stops_provisional": sum(bool(s.get("provisional")) for s in out.reflex.get("stops", [])),
        "provisional_onsets": int(c.get("provisional_onsets", 0)),
        "provisional_unconfirmed": int(c.get("provisional_unconfirmed", 0)),
        "onsets_without_provisional": int(c.get("onsets_without_provisional", 0)),
        "reflex_errors": list(out.reflex.get("errors", [])),
        "cpu_share": cpu.busy_share(),
        "degraded": list(out.degraded), "problems": list(out.problems), "device_counters": out.device_counters,
    }
