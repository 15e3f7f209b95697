"""A UR recording as the pipeline's inputs: one :class:`~ftc_hw.monitor.PipelineInput` per kept row,
joint-driven (the scene's sensing has no base F/T sensor; a UR has none), so that ``ftc replay FILE.csv``
runs the same monitor as a live arm.

Times: the ``timestamp`` column (the controller's clock, s) is both the device time and the host time
of each input (ns; a recording has no host clock). A step longer than 1.5 times the median step (missed
or dropped rows: real UR logs at about 100 Hz jitter from 8 to 34 ms) is a joint gap, as live.
"""
from __future__ import annotations

import numpy as np

from ftc_hw.monitor import PipelineInput
from ftc_hw.scene import Scene

from .errors import URCsvError
from .recording import SENSING_OF, URRecording

GAP_STEPS = 1.5  # a step beyond this many median steps spans missed rows


def check_fits(rec: URRecording, scene: Scene) -> None:
    """A ``URCsvError`` when the recording cannot feed the scene's pipeline: another number of joints,
    a base F/T sensor in the scene's sensing, or a sensing the columns do not hold."""
    if rec.n_joints != scene.n_joints:
        raise URCsvError(str(rec.path), None, f"{rec.n_joints} joints recorded, scene {scene.name!r} has "
                                              f"{scene.n_joints}")
    sensing = scene.sensing
    if sensing.ft == "base":
        raise URCsvError(str(rec.path), None, f"scene {scene.name!r} uses a base F/T sensor, which a UR "
                                              "recording does not hold: choose --sensing from what it holds "
                                              f"({', '.join(sorted(rec.sensing)) or 'nothing'})")
    missing = sorted(k for k in sensing.kinds if k not in rec.sensing)
    if missing:
        columns = {kind: col for col, kind in SENSING_OF.items()}
        raise URCsvError(str(rec.path), None, f"scene {scene.name!r} uses {', '.join(missing)}, but the file has "
                                              f"no {', '.join(columns.get(k, k) for k in missing)} column: "
                                              f"--sensing {','.join(sorted(rec.sensing)) or '...'}")


def pipeline_inputs(rec: URRecording, scene: Scene, *, tare_s: float | None = None) -> list[PipelineInput]:
    """The recording's rows as pipeline inputs for ``scene`` (:func:`check_fits` first). ``tare_s``: the
    first that many seconds tare the flange sensor (None: the calibration's bias is used)."""
    check_fits(rec, scene)
    t_ns = np.round(rec.t * 1e9).astype(np.int64)
    steps = np.diff(t_ns, prepend=t_ns[0])
    median = float(np.median(steps[1:])) if len(steps) > 1 else 0.0
    gaps = np.where(steps > GAP_STEPS * median, steps, 0)
    use_ft = scene.sensing.ft == "flange"
    ranges = scene.sensor.range if use_ft and scene.sensor is not None else None
    current = rec.current if rec.current is not None else np.zeros_like(rec.q)
    tare_until = t_ns[0] + int(tare_s * 1e9) if use_ft and tare_s is not None else None
    out = []
    for i, t in enumerate(t_ns):
        wrench = rec.ft_raw_wrench[i] if use_ft else np.zeros(0)
        saturated = bool(ranges is not None and np.any(np.abs(wrench) >= ranges))
        out.append(PipelineInput(int(t), int(t), i, "arm", wrench, rec.q[i], rec.qd[i], current[i], saturated,
                                 tare=tare_until is not None and t <= tare_until, joint_gap_ns=int(gaps[i])))
    return out
