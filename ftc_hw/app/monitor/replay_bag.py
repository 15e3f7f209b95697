"""``ftc replay BAG --scene S [--topics map.toml]``: a ROS 2 bag of a cell's drivers (joint states, a
wrench) through the monitor a live arm runs (:mod:`ftc_hw.app.ros.bag_inputs`). What the bag holds
(topics, messages kept and skipped by reason, timing) is said first; it holds no events to compare with."""
from __future__ import annotations

from rich.console import Console

from ftc_hw.bus import EVENTS_CONTACT, Bus, ContactEvent
from ftc_hw.monitor import LiveMonitor
from ftc_hw.pipeline import Corrections, PipelineSettings
from ftc_hw.record.reader import RecordingError
from ftc_hw.scene import SceneError, load_scene

from .config import MonitorSetupError, ReplayOptions
from .replay_csv import TARE_S, CsvReplayResult, say_replayed
from .session import load_pipeline_calibration


def run_bag_replay(options: ReplayOptions, console: Console) -> CsvReplayResult:
    """The bag read and said, replayed through the scene's monitor, its events written."""
    from ftc_hw.app.ros import RosUnavailable, require_ros  # lazy: the ros extra, for bags only

    if options.scene is None:
        raise MonitorSetupError(f"{options.recording}: a ROS 2 bag holds no scene: give --scene (ur10e, fr3, ...)")
    try:
        require_ros("ftc replay of a ROS 2 bag")
        from ftc_hw.app.ros.bag_inputs import bag_sensing, drive  # lazy: rosbags, after require_ros
        from ftc_hw.app.ros.bag_read import read_bag  # lazy: rosbags, after require_ros
        from ftc_hw.app.ros.topic_map import default_map, load_topic_map  # lazy: beside the bag reader

        scene = load_scene(options.scene)
        tmap = load_topic_map(options.topics, scene) if options.topics else default_map(scene)
        bag = read_bag(options.recording, tmap, scene)
        held = bag_sensing(bag, scene)
        if options.sensing is not None:
            scene = scene.with_sensing(options.sensing)
        elif not scene.sensing.kinds <= held:  # what the bag allows of what the scene has
            scene = scene.with_sensing(scene.available.kinds & held)
    except (RosUnavailable, RecordingError, OSError, ValueError) as exc:  # SceneError, TopicMapError: ValueErrors
        raise MonitorSetupError(str(exc)) from None
    corrections = load_pipeline_calibration(options.calibration, scene)[0] if options.calibration else None
    console.print(bag.summary())
    console.print(f"scene {scene.name}, sensing used: {scene.sensing.label()}"
                  + ("" if corrections else " [yellow](no --calibration: the nominal model; ftc identify first)[/]"))
    bus = Bus()
    sub = bus.subscribe(EVENTS_CONTACT, maxsize=None)
    monitor = LiveMonitor(bus, scene, tare_s=None if corrections else TARE_S, publish_inputs=False,
                          settings=PipelineSettings(corrections=corrections or Corrections()))
    try:
        handled = drive(monitor, bag)
    except (RecordingError, SceneError) as exc:
        raise MonitorSetupError(str(exc)) from None
    events = [e for e in sub.drain() if isinstance(e, ContactEvent)]
    return say_replayed(CsvReplayResult(bag, handled, events, dict(monitor.counters)), options, console, "messages")
