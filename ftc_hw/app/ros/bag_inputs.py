"""A bag's streams (:mod:`.bag_read`) into the monitor a live arm runs, and into the identification's
stretches of motion. No ROS import.

Times: a message's header stamp is the device time of its frame and the bag's receive time (when the
recorder got it) its host time, so the monitor aligns the clocks as it does live. The frames reach the
monitor in stamp order, a driving frame once the side stream has passed its stamp (as the live monitor
waits for it), in this thread: there is no wall clock in a replay, so a stream's silence is a gap the
monitor sees in the stamps (``joint_gap``, ``no_ft_state_gap``), not a ``*_lost`` event.
"""
from __future__ import annotations

from collections import deque

import numpy as np

from ftc_hw.bus import JointFrame, WrenchFrame
from ftc_hw.bus.history import SamplingPolicy, StateHistory
from ftc_hw.calibration.free_motion import MotionData
from ftc_hw.calibration.joint_motion import JointMotionData
from ftc_hw.monitor import LiveMonitor
from ftc_hw.scene import Scene

from .bag_read import BagError, BagRecording

SPLIT_STEPS = 3.0  # identification: a step longer than this many median steps ends a stretch
MAX_GAP_NS = 20_000_000  # identification, F/T-driven: the joint state is interpolated over at most this


def bag_sensing(bag: BagRecording, scene: Scene) -> frozenset[str]:
    """The scene sensing kinds the bag holds (its wrench as the scene's sensor, by its mount)."""
    kinds = set(bag.sensing)
    if "ft" in kinds:
        kinds.discard("ft")
        if scene.sensor is not None:
            kinds.add("base_ft" if scene.sensor.mount == "base" else "flange_ft")
    return frozenset(kinds)


def check_fits(bag: BagRecording, scene: Scene) -> None:
    """A :class:`BagError` when the bag cannot feed the scene's pipeline: another number of joints, or a
    sensing the mapped topics do not hold."""
    if bag.n_joints != scene.n_joints:
        raise BagError(f"{bag.path}: {bag.n_joints} joints mapped, scene {scene.name!r} has {scene.n_joints}")
    held = bag_sensing(bag, scene)
    missing = sorted(k for k in scene.sensing.kinds if k not in held)
    if missing:
        raise BagError(f"{bag.path}: scene {scene.name!r} uses {', '.join(missing)}, which the bag's mapped topics do "
                       f"not hold (they hold {', '.join(sorted(held)) or 'joint positions only'}): --sensing "
                       f"{','.join(sorted(held)) or '...'}, or map the topics (--topics)")


def _frames(bag: BagRecording, scene: Scene, ft_source: str, arm_source: str) -> list[tuple[int, str, object]]:
    """(stamp ns, "arm" | "sensor", frame) of both streams, in stamp order (the arm first on a tie)."""
    js = bag.joints
    eff = js.values.get("effort")
    effort = bag.topic_map.joint_states.effort
    n = scene.n_joints
    zeros = np.zeros(n)
    out: list[tuple[int, str, object]] = []
    for i, (t, log) in enumerate(zip(js.t_ns.tolist(), js.log_ns.tolist(), strict=True)):
        current = eff[i] if effort == "current" else zeros
        tau = eff[i] if effort == "torque" else None
        out.append((t, "arm", JointFrame.make(log, js.values["q"][i], js.values["qd"][i], current, tau,
                                              source=arm_source, seq=i, t_device_ns=t)))
    if bag.wrench is not None and scene.sensing.ft is not None:
        w = bag.wrench
        for i, (t, log) in enumerate(zip(w.t_ns.tolist(), w.log_ns.tolist(), strict=True)):
            out.append((t, "sensor", WrenchFrame.make(log, w.values["wrench"][i], source=ft_source, seq=i,
                                                      t_device_ns=t)))
    out.sort(key=lambda x: (x[0], x[1] != "arm"))
    return out


def drive(monitor: LiveMonitor, bag: BagRecording, *, ft_source: str = "ft", arm_source: str = "arm") -> int:
    """Every mapped message of ``bag`` through ``monitor`` (made with these sources, not started: no
    thread); returns the driving frames handed to it. Events go on the monitor's bus as live."""
    check_fits(bag, monitor.scene)
    driving = "sensor" if monitor.driver == "ft" else "arm"
    side = monitor.on_joints if driving == "sensor" else monitor.on_wrench if monitor.uses_ft else None
    pending: deque = deque()
    handled = 0
    for t, stream, frame in _frames(bag, monitor.scene, ft_source, arm_source):
        if stream == driving:
            if side is None:
                monitor.handle(frame)
                handled += 1
            else:
                pending.append((t, frame))
            continue
        side(frame)
        while pending and pending[0][0] <= t:
            monitor.handle(pending.popleft()[1])
            handled += 1
    for _, frame in pending:  # the side stream ended first: what is left is judged as live, past its end
        monitor.handle(frame)
        handled += 1
    return handled


def _runs(t_ns: np.ndarray) -> list[slice]:
    """Index ranges without a step longer than SPLIT_STEPS median steps, two samples or more each."""
    steps = np.diff(t_ns)
    if not len(steps):
        return []
    breaks = np.flatnonzero(steps > SPLIT_STEPS * np.median(steps)) + 1
    edges = [0, *breaks.tolist(), len(t_ns)]
    return [slice(a, b) for a, b in zip(edges[:-1], edges[1:], strict=True) if b - a >= 2]


def joint_motion(bag: BagRecording, scene: Scene) -> list[JointMotionData]:
    """The joint states as stretches of motion (split at gaps), on the stamps' clock, in the scene's order."""
    check_fits(bag, scene)
    js = bag.joints
    effort = bag.topic_map.joint_states.effort
    eff = js.values.get("effort")
    out = []
    for r in _runs(js.t_ns):
        t = (js.t_ns[r] - js.t_ns[r][0]) * 1e-9
        out.append(JointMotionData(t, js.values["q"][r], js.values["qd"][r],
                                   current=eff[r] if effort == "current" else None,
                                   tau_j=eff[r] if effort == "torque" else None))
    return out


def ft_motion(bag: BagRecording, scene: Scene) -> tuple[list[MotionData], dict[str, int]]:
    """F/T-driven (a base sensor): each wrench with the joint state interpolated at its stamp, in stretches
    split where the joint state is missing; and how many wrench samples had none (``no_joint_state``)."""
    check_fits(bag, scene)
    js, w = bag.joints, bag.wrench
    n = scene.n_joints
    eff = js.values.get("effort") if bag.topic_map.joint_states.effort == "current" else None
    x = np.hstack([js.values["q"], js.values["qd"], eff if eff is not None else np.zeros((len(js.t_ns), n))])
    history = StateHistory(SamplingPolicy(MAX_GAP_NS, "linear", 0), maxlen=len(js.t_ns) + 1)
    for t, row in zip(js.t_ns.tolist(), x, strict=True):
        history.add(t, row)
    states = [history.at(t) for t in w.t_ns.tolist()]
    ok = np.array([not isinstance(s, str) for s in states])
    t_ok = w.t_ns[ok]
    xs = np.array([s[0] for s in states if not isinstance(s, str)]).reshape(-1, 3 * n)
    wrench = w.values["wrench"][ok]
    out = []
    for r in _runs(t_ok):
        out.append(MotionData((t_ok[r] - t_ok[r][0]) * 1e-9, wrench[r], xs[r, :n], xs[r, n:2 * n],
                              xs[r, 2 * n:] if eff is not None else None))
    return out, {"frames": len(w.t_ns), "no_joint_state": int((~ok).sum())}
