"""Bus frames as JSON messages with JSON Schemas (MCAP ``jsonschema`` schema / ``json`` message encoding).

Floats are written in their shortest round-trip form: a decoded frame is bit-for-bit the one that was
recorded (what makes a replay reproduce the events). orjson writes them (a 7 kHz F/T stream and its
pipeline inputs cost 21 us a sample with the standard library's ``json``, most of the recorder's
share of a core); a message with a non-finite number, which orjson would write as ``null``, is
written by ``json`` as before (``NaN``, ``Infinity``), and read back by it.
"""
from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import orjson

from ftc_hw.bus import ContactEvent, DeviceEvent, JointFrame, WrenchFrame, frame_topic
from ftc_hw.monitor import MONITOR_INPUT, MONITOR_JUDGED, JudgedFrame, PipelineInput

from .events import LIMIT_FIELDS, limit_check_of, limit_record

_INT = {"type": "integer"}
_STR = {"type": "string"}
_NUM = {"type": "number"}
# a contact event's judgement against its body region's limits (docs/limits.md): the recordings' and ROS's
LIMITS_JSON_SCHEMA = {"type": "object", "description": "the event against its body region's limits (docs/limits.md)",
                      "properties": {"region": _STR, "region_from": _STR, "limit_kind": _STR,
                                     "class_assumed": {"type": "boolean"}, "limit_n": _NUM, "margin_n": _NUM,
                                     "effective_mass_kg": _NUM, "speed_mps": _NUM, "permissible_speed_mps": _NUM},
                      "required": list(LIMIT_FIELDS), "additionalProperties": False}
_DEVICE_TIME = {"type": ["integer", "null"], "description": "device clock, ns (null: the device sends none)"}


def _vec(n: int | None, unit: str) -> dict[str, Any]:
    s: dict[str, Any] = {"type": "array", "items": _NUM, "description": unit}
    if n is not None:
        s.update(minItems=n, maxItems=n)
    return s


def _schema(title: str, description: str, props: dict[str, Any], optional: tuple[str, ...] = ()) -> dict:
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": title, "description": description,
            "type": "object", "properties": props, "required": [k for k in props if k not in optional]}


_HOST = {"type": "integer", "description": "host time.monotonic_ns()"}
SCHEMAS: dict[str, dict[str, Any]] = {
    "ftc_hw.WrenchFrame": _schema("ftc_hw.WrenchFrame", "one F/T sample, sensor frame, scene sign convention", {
        "t_host_ns": _HOST, "t_device_ns": _DEVICE_TIME, "seq": _INT, "source": _STR,
        "wrench": _vec(6, "[fx, fy, fz] N, [tx, ty, tz] N m"), "flags": _INT}),
    "ftc_hw.JointFrame": _schema("ftc_hw.JointFrame", "joint state in the scene's joint order", {
        "t_host_ns": _HOST, "t_device_ns": _DEVICE_TIME, "seq": _INT, "source": _STR, "q": _vec(None, "rad"),
        "qd": _vec(None, "rad/s"), "current": _vec(None, "A"), "tau": {"type": ["array", "null"], "items": _NUM},
        "flags": _INT}),
    "ftc_hw.ContactEvent": _schema("ftc_hw.ContactEvent", "contact onset/update/offset/exceedance, base frame", {
        "t_host_ns": _HOST, "kind": {"enum": ["onset", "update", "offset", "exceedance"]}, "link": _STR,
        "point": _vec(3, "m"), "force": _vec(3, "N applied to the arm"), "point_std": _vec(3, "m, 1 sigma"),
        "flags": {"type": "array", "items": _STR}, "probability": _NUM,
        "contact_id": {"type": "integer", "description": "pairs a contact's events (from 1; absent in older "
                       "recordings)"},
        "duration_s": {"type": "number", "description": "s since the contact's onset"},
        "peak_force": {"type": "number", "description": "N, the contact's largest external force so far"},
        "impulse": {"type": "number", "description": "N s, the external force's magnitude integrated"},
        "contact_class": {"enum": ["", "transient", "quasi_static", "unknown"],
                          "description": "the contact's class so far (final at the offset; docs/contacts.md)"},
        "p_quasi_static": {"type": "number", "description": "probability that the contact is quasi-static (clamped)"},
        "intent": {"enum": ["", "impact", "guidance", "unknown"], "description": "accidental or guided"},
        "p_guidance": {"type": "number", "description": "probability that a person is guiding the arm"},
        "class_features": {"type": "object", "additionalProperties": _NUM,
                           "description": "the features the class was drawn from (SI)"},
        "limits": LIMITS_JSON_SCHEMA},
        optional=("contact_id", "duration_s", "peak_force", "impulse", "contact_class", "p_quasi_static", "intent",
                  "p_guidance", "class_features", "limits")),
    "ftc_hw.DeviceEvent": _schema("ftc_hw.DeviceEvent", "device or stream event", {
        "t_host_ns": _HOST, "source": _STR, "kind": _STR, "message": _STR,
        "counters": {"type": "object", "additionalProperties": _NUM}}),
    "ftc_hw.PipelineInput": _schema("ftc_hw.PipelineInput", "one sample as the contact pipeline consumed it: "
                                    "aligned time, raw wrench, joint state interpolated at that time (or, a scene "
                                    "sensed without a base F/T sensor, a joint sample and the F/T reading there)", {
        "t_host_ns": {"type": "integer", "description": "the sample's aligned host time, ns"},
        "t_device_ns": _DEVICE_TIME, "seq": _INT, "source": _STR,
        "wrench": _vec(None, "N, N m: 6 values, or none where no F/T sensor is used"),
        "q": _vec(None, "rad"), "qd": _vec(None, "rad/s"), "current": _vec(None, "A"),
        "saturated": {"type": "boolean"}, "tare": {"type": "boolean"},
        "joint_gap_ns": {"type": "integer", "description": "> 0: the joint state spans missed joint samples "
                         "(ns between them); absent in older recordings"},
        "tau_j": {"type": ["array", "null"], "items": _NUM,
                  "description": "N m, the joint torque sensors' reading where used; absent in older recordings"}},
        optional=("joint_gap_ns", "tau_j")),
    "ftc_hw.JudgedFrame": _schema("ftc_hw.JudgedFrame", "what the pipeline made of one input (recorded when the "
                                  "monitor publishes them: ROS outputs)", {
        "t_host_ns": {"type": "integer", "description": "the input's aligned host time, ns"},
        "t_device_ns": _DEVICE_TIME, "seq": _INT, "source": _STR,
        "external": _vec(6, "N, N m: the external contact wrench, sensor frame, scene sign convention"),
        "d2": {"type": "number", "description": "the detection statistic (chi-square)"},
        "in_contact": {"type": "boolean"}}),
}


def _list(a) -> list[float]:
    return np.asarray(a, dtype=np.float64).tolist()  # Python floats: the same JSON as float(x), 10x faster


def topic_of(frame: Any) -> str | None:
    """The topic a frame is published on (the bus conventions), None for an unknown type."""
    if isinstance(frame, PipelineInput):
        return MONITOR_INPUT
    return MONITOR_JUDGED if isinstance(frame, JudgedFrame) else frame_topic(frame)


def encode(frame: Any) -> tuple[str, bytes]:
    """(schema name, JSON bytes)."""
    if isinstance(frame, WrenchFrame):
        name, d = "ftc_hw.WrenchFrame", {"t_host_ns": frame.t_host_ns, "t_device_ns": frame.t_device_ns,
                                         "seq": frame.seq, "source": frame.source, "wrench": _list(frame.wrench),
                                         "flags": int(frame.flags)}
    elif isinstance(frame, JointFrame):
        name, d = "ftc_hw.JointFrame", {"t_host_ns": frame.t_host_ns, "t_device_ns": frame.t_device_ns,
                                        "seq": frame.seq, "source": frame.source, "q": _list(frame.q),
                                        "qd": _list(frame.qd), "current": _list(frame.current),
                                        "tau": None if frame.tau is None else _list(frame.tau),
                                        "flags": int(frame.flags)}
    elif isinstance(frame, ContactEvent):
        name, d = "ftc_hw.ContactEvent", {"t_host_ns": frame.t_host_ns, "kind": frame.kind, "link": frame.link,
                                          "point": _list(frame.point), "force": _list(frame.force),
                                          "point_std": _list(frame.point_std), "flags": list(frame.flags),
                                          "probability": float(frame.probability), "contact_id": frame.contact_id,
                                          "duration_s": frame.duration_s, "peak_force": frame.peak_force,
                                          "impulse": frame.impulse, "contact_class": frame.contact_class,
                                          "p_quasi_static": frame.p_quasi_static, "intent": frame.intent,
                                          "p_guidance": frame.p_guidance,
                                          "class_features": {k: float(v) for k, v in frame.class_features.items()}}
        if frame.limits is not None:
            d["limits"] = limit_record(frame.limits)
    elif isinstance(frame, DeviceEvent):
        name, d = "ftc_hw.DeviceEvent", {"t_host_ns": frame.t_host_ns, "source": frame.source, "kind": frame.kind,
                                         "message": frame.message,
                                         "counters": {k: float(v) for k, v in frame.counters.items()}}
    elif isinstance(frame, PipelineInput):
        name, d = "ftc_hw.PipelineInput", {"t_host_ns": frame.t_host_ns, "t_device_ns": frame.t_device_ns,
                                           "seq": frame.seq, "source": frame.source, "wrench": _list(frame.wrench),
                                           "q": _list(frame.q), "qd": _list(frame.qd),
                                           "current": _list(frame.current), "saturated": bool(frame.saturated),
                                           "tare": bool(frame.tare), "joint_gap_ns": int(frame.joint_gap_ns),
                                           "tau_j": None if frame.tau_j is None else _list(frame.tau_j)}
    elif isinstance(frame, JudgedFrame):
        name, d = "ftc_hw.JudgedFrame", {"t_host_ns": frame.t_host_ns, "t_device_ns": frame.t_device_ns,
                                         "seq": frame.seq, "source": frame.source, "external": _list(frame.external),
                                         "d2": float(frame.d2), "in_contact": bool(frame.in_contact)}
    else:
        raise TypeError(f"no schema for {type(frame).__name__}")
    try:
        data = orjson.dumps(d)
    except orjson.JSONEncodeError:  # a NumPy scalar (a float subclass to json): json's text, as before
        return name, json.dumps(d, separators=(",", ":")).encode()
    if b"null" in data and not _finite(d):
        data = json.dumps(d, separators=(",", ":")).encode()
    return name, data


def _finite(x: Any) -> bool:
    """No NaN or infinity anywhere in a message's values."""
    if isinstance(x, float):
        return math.isfinite(x)
    if isinstance(x, dict):
        return all(_finite(v) for v in x.values())
    if isinstance(x, list):
        return all(_finite(v) for v in x)
    return True


def _loads(data: bytes) -> Any:
    try:
        return orjson.loads(data)
    except orjson.JSONDecodeError:  # NaN or Infinity (see the module doc), or not JSON at all
        return json.loads(data)


def decode(schema: str, data: bytes) -> Any:
    """The frame a message holds (validated by the frames' ``make``); ValueError on a bad message."""
    d = _loads(data)
    if schema == "ftc_hw.WrenchFrame":
        return WrenchFrame.make(d["t_host_ns"], d["wrench"], source=d["source"], seq=d["seq"],
                                t_device_ns=d["t_device_ns"], flags=d["flags"])
    if schema == "ftc_hw.JointFrame":
        return JointFrame.make(d["t_host_ns"], d["q"], d["qd"], d["current"], d["tau"], source=d["source"],
                               seq=d["seq"], t_device_ns=d["t_device_ns"], flags=d["flags"])
    if schema == "ftc_hw.ContactEvent":
        return ContactEvent.make(d["t_host_ns"], d["kind"], d["link"], d["point"], d["force"], d["point_std"],
                                 flags=d["flags"], probability=d["probability"], contact_id=d.get("contact_id", 0),
                                 duration_s=d.get("duration_s", 0.0), peak_force=d.get("peak_force", 0.0),
                                 impulse=d.get("impulse", 0.0), contact_class=d.get("contact_class", ""),
                                 p_quasi_static=d.get("p_quasi_static", 0.5), intent=d.get("intent", ""),
                                 p_guidance=d.get("p_guidance", 0.5), class_features=d.get("class_features"),
                                 limits=limit_check_of(d.get("limits")))
    if schema == "ftc_hw.DeviceEvent":
        return DeviceEvent.make(d["t_host_ns"], d["source"], d["kind"], d["message"], d["counters"])
    if schema == "ftc_hw.PipelineInput":
        def arr(k: str) -> np.ndarray:
            a = np.array(d[k], dtype=np.float64)
            if a.ndim != 1 or not np.isfinite(a).all():
                raise ValueError(f"PipelineInput.{k}: expected a finite vector")
            return a

        wrench = arr("wrench")
        if wrench.shape[0] not in (0, 6):
            raise ValueError(f"PipelineInput.wrench: expected 6 values or none, got {wrench.shape[0]}")
        return PipelineInput(int(d["t_host_ns"]), d["t_device_ns"], int(d["seq"]), str(d["source"]), wrench,
                             arr("q"), arr("qd"), arr("current"), bool(d["saturated"]), bool(d["tare"]),
                             int(d.get("joint_gap_ns", 0)), None if d.get("tau_j") is None else arr("tau_j"))
    if schema == "ftc_hw.JudgedFrame":
        external = np.array(d["external"], dtype=np.float64)
        if external.shape != (6,):
            raise ValueError(f"JudgedFrame.external: expected 6 values, got {external.shape}")
        return JudgedFrame(int(d["t_host_ns"]), d["t_device_ns"], int(d["seq"]), str(d["source"]), external,
                           float(d["d2"]), bool(d["in_contact"]))
    raise ValueError(f"unknown schema {schema!r}")
