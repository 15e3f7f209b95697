"""``ftc monitor --record-format ros2|both``: a ROS 2 bag (rosbag2's layout: a directory with
``metadata.yaml`` and one MCAP file of the ``ros2`` profile, ``ros2msg`` schemas, CDR messages) written by
rosbags in the recorder's process, from the frames it is handed (:class:`~ftc_hw.record.writer_process.Sink`).

It holds what ``--ros`` publishes and what only a bag can (``/tf``; the raw inputs as the drivers publish
them), each topic with the QoS ``--ros`` offers (a latched topic plays back latched), and 1 Hz diagnostics
on the frames' clock. Log times are the messages' ROS stamps.
"""
from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import StoragePlugin, Writer

from ftc_hw.record.writer_process import Sink
from ftc_hw.scene import Scene

from . import encode as enc
from . import layout as L
from .view import RosMessage, RosView

DIAGNOSTICS_NS = 1_000_000_000
_NO_TIME = QosTime(sec=0x7FFFFFFF, nsec=0xFFFFFFFF)  # rosbag2's "infinite" duration


def bag_path(record: Path, record_format: str) -> Path:
    """Where the bag goes: ``record`` itself with ``ros2``; beside the ftc file as ``<stem>_ros2`` with ``both``."""
    return record if record_format == "ros2" else record.with_name(f"{record.stem}_ros2")


def offered_qos(topic: L.Topic) -> Qos:
    durability = QosDurability.TRANSIENT_LOCAL if topic.latched else QosDurability.VOLATILE
    return Qos(history=QosHistory.KEEP_LAST, depth=topic.depth, reliability=QosReliability.RELIABLE,
               durability=durability, deadline=_NO_TIME, lifespan=_NO_TIME, liveliness=QosLiveliness.AUTOMATIC,
               liveliness_lease_duration=_NO_TIME, avoid_ros_namespace_conventions=False)


def bag_sink(*, path: Path, scene: Scene, namespace: str = L.DEFAULT_NAMESPACE) -> Sink:
    """The recorder process's sink that writes the bag at ``path`` (a directory that must not exist)."""
    return Sink(RosBagWriter, {"path": str(path), "scene": scene, "namespace": namespace})


class RosBagWriter:
    """``write(frame)``, ``flush()``, ``finish(final_metadata) -> summary``: the writer process's sink."""

    def __init__(self, *, path: str, scene: Scene, namespace: str = L.DEFAULT_NAMESPACE) -> None:
        self.path, self.namespace = Path(path), namespace
        self.view = RosView(scene, namespace=namespace, bag=True)
        self.counts: Counter[str] = Counter()
        self._writer = Writer(self.path, version=Writer.VERSION_LATEST, storage_plugin=StoragePlugin.MCAP)
        self._writer.open()
        self._connections: dict[str, Any] = {}
        self._next_diag: int | None = None

    def _connection(self, topic: L.Topic) -> Any:
        name = topic.full_name(self.namespace)
        conn = self._connections.get(name)
        if conn is None:
            conn = self._writer.add_connection(name, topic.msgtype, typestore=enc.typestore(),
                                               offered_qos_profiles=[offered_qos(topic)])
            self._connections[name] = conn
        return conn

    def _write(self, messages: list[RosMessage]) -> None:
        for m in messages:
            self._writer.write(self._connection(m.topic), m.t_ns, m.data)
            self.counts[m.topic.full_name(self.namespace)] += 1

    def write(self, frame: Any) -> None:
        t = getattr(frame, "t_host_ns", None)
        if t is not None:
            if self._next_diag is None:
                self._next_diag = t + DIAGNOSTICS_NS
            elif t >= self._next_diag:  # the streams' health each second of the frames' clock
                self._next_diag += DIAGNOSTICS_NS * (1 + (t - self._next_diag) // DIAGNOSTICS_NS)
                self._write([self.view.diagnostics(t)])
        self._write(self.view.feed(frame))

    def flush(self) -> None:
        pass  # rosbags' MCAP writer writes its chunks as they fill; a killed recorder loses the last one

    def finish(self, final_metadata: dict | None = None) -> dict[str, Any]:
        self._writer.close()
        return {"path": str(self.path), "counts": dict(self.counts), "skipped": dict(self.view.skipped)}
