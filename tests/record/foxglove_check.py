"""Reads a recording's Foxglove channels with the ``mcap`` library alone, as Foxglove would: each
message checked against the JSON Schema stored in the file (Foxglove's own, ``jsonschema``), the
frame transforms composed into poses in the root frame. Independent of the recorder's code: poses
from quaternions by the textbook formula, times from ``{"sec", "nsec"}``."""
from __future__ import annotations

import json
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from jsonschema.validators import validator_for
from mcap.reader import make_reader

from ftc_hw.record.foxglove_messages import foxglove_schema


def ns(stamp: dict) -> int:
    return stamp["sec"] * 1_000_000_000 + stamp["nsec"]


def matrix(position: dict, q: dict) -> np.ndarray:
    x, y, z, w = q["x"], q["y"], q["z"], q["w"]
    n = x * x + y * y + z * z + w * w
    assert abs(n - 1.0) < 1e-6, f"not a unit quaternion: {q}"
    out = np.eye(4)
    out[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                   [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                   [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    out[:3, 3] = [position["x"], position["y"], position["z"]]
    return out


def of_pose(p: dict) -> np.ndarray:
    return matrix(p["position"], p["orientation"])


@dataclass
class FoxgloveFile:
    schemas: dict[str, str] = field(default_factory=dict)  # topic -> schema name
    messages: dict[str, list[dict]] = field(default_factory=lambda: defaultdict(list))  # topic -> decoded, in order
    bus: dict[str, list[dict]] = field(default_factory=lambda: defaultdict(list))  # the bus's own JSON channels
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    # (child frame, t ns) -> (parent frame, parent_T_child)
    transforms: dict[tuple[str, int], tuple[str, np.ndarray]] = field(default_factory=dict)

    def pose(self, frame: str, t_ns: int, root: str = "world") -> np.ndarray:
        """root_T_frame from the transforms stamped exactly t_ns."""
        out = np.eye(4)
        while frame != root:
            parent, p_T_c = self.transforms[(frame, t_ns)]
            out = p_T_c @ out
            frame = parent
        return out

    def entities(self, topic: str) -> list[dict]:
        return [e for m in self.messages[topic] for e in m["entities"]]


def read_foxglove(path: Path) -> FoxgloveFile:
    """Every ``foxglove.*`` message decoded and validated against its channel's schema in the file,
    which must be Foxglove's own (the packaged copy)."""
    out = FoxgloveFile()
    validators = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        out.metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        f.seek(0)
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            data = json.loads(message.data)
            if not schema.name.startswith("foxglove."):
                out.bus[channel.topic].append(data)
                continue
            assert schema.encoding == "jsonschema" and channel.message_encoding == "json"
            if schema.id not in validators:
                body = json.loads(schema.data)
                assert body == foxglove_schema(schema.name), f"{schema.name}: not Foxglove's schema"
                cls = validator_for(body)
                cls.check_schema(body)
                validators[schema.id] = cls(body)
            errors = [e.message for e in validators[schema.id].iter_errors(data)]
            assert not errors, f"{channel.topic} at {message.log_time}: {errors[:3]}"
            out.schemas[channel.topic] = schema.name
            out.messages[channel.topic].append(data)
            if schema.name == "foxglove.FrameTransforms":
                for tf in data["transforms"]:
                    out.transforms[(tf["child_frame_id"], ns(tf["timestamp"]))] = (
                        tf["parent_frame_id"], matrix(tf["translation"], tf["rotation"]))
    return out


def estimate_times(events: list[dict]) -> dict[int, int]:
    """Per event (by index): the time of the estimate it shows. An offset carries its contact's last
    sound estimate: the time of the newest earlier event of that contact with the same link and point."""
    out = {}
    for i, ev in enumerate(events):
        out[i] = ev["t_host_ns"]
        if ev["kind"] == "offset":
            same = [e for e in events[:i] if e.get("contact_id") == ev.get("contact_id") and e["link"] == ev["link"]
                    and e["point"] == ev["point"] and e["kind"] != "offset"]
            if same:
                out[i] = same[-1]["t_host_ns"]
    return out


def contact_markers_in_base(fox: FoxgloveFile) -> list[tuple[dict, np.ndarray, dict]]:
    """(event, the marker's centre composed into the root frame, its entity) for every contact entity,
    matched to the ``events/contact`` message it was made from."""
    events = fox.bus["events/contact"]
    when = estimate_times(events)
    by_key = {(ev["t_host_ns"], ev["kind"], ev.get("contact_id", 0)): i for i, ev in enumerate(events)}
    out = []
    for ent in fox.entities("foxglove/contacts"):
        meta = {kv["key"]: kv["value"] for kv in ent["metadata"]}
        i = by_key[(int(meta["t_host_ns"]), meta["kind"], int(meta["contact_id"]))]
        assert ns(ent["timestamp"]) == events[i]["t_host_ns"] and ent["frame_id"] == events[i]["link"]
        marker = ent["spheres"][0]
        base_T_link = fox.pose(ent["frame_id"], when[i])
        out.append((events[i], (base_T_link @ of_pose(marker["pose"]))[:3, 3], ent))
    return out
