"""The recorder's Foxglove channels on a synthetic ur5e bus (a sweeping arm, its F/T stream, the
pipeline's inputs and a contact's events): they exist, every message is valid against Foxglove's
own schema stored in the file, composing the file's transforms puts each contact marker on the
event's point and each surface where the model has it; the bus's channels are the same bytes with
them or without; bad frames are counted, never fatal."""
from __future__ import annotations

import time

import numpy as np
import pytest
from mcap.reader import make_reader

from ftc_hw.bus import Bus, ContactEvent, JointFrame, WrenchFrame
from ftc_hw.model import ArmModel
from ftc_hw.monitor import MONITOR_INPUT, PipelineInput
from ftc_hw.record.foxglove_messages import K95_3D
from ftc_hw.record.reader import read_recording
from ftc_hw.record.replay import recorded_scene
from ftc_hw.record.writer import McapRecorder
from ftc_hw.scene import load_scene
from tests.record.foxglove_check import contact_markers_in_base, matrix, of_pose, read_foxglove

pytestmark = pytest.mark.compute  # files and frames made as fast as they go: nothing timed

T0 = 5_000_000_000
SCENE = load_scene("ur5e")
ARM = ArmModel(SCENE)
POINT_FOREARM = np.array([0.0, 0.05, 0.2])  # a point fixed on the forearm (its own frame)
FOXGLOVE_TOPICS = {"foxglove/tf", "foxglove/arm", "foxglove/contacts", "foxglove/wrench"}


def q_at(t_ns: int) -> np.ndarray:
    """A sweep of every joint, ~1 rad/s: 20 ms of it moves the forearm by centimetres."""
    s = (t_ns - T0) / 1e9
    return np.asarray(SCENE.robot.home) + 0.6 * np.sin(1.7 * s + np.arange(6))


def on_forearm(t_ns: int) -> np.ndarray:
    b_T_l = ARM.kinematics(q_at(t_ns))["forearm"]
    return b_T_l[:3, :3] @ POINT_FOREARM + b_T_l[:3, 3]


def frames(seconds: float = 1.0, *, inputs: bool = True) -> list[tuple[str, object]]:
    """1 kHz F/T and pipeline inputs, 500 Hz joints (received 0.3 ms after their instant), and one
    contact: its onset published a sample late (as the pipeline does), updates every 20 ms, an offset
    carrying the last update's estimate, and an onset without an estimate."""
    out: list[tuple[str, object]] = []
    contact = {200: "onset", 220: "update", 240: "update", 260: "update", 283: "offset"}
    for k in range(int(seconds * 1000)):
        t = T0 + k * 1_000_000
        q = q_at(t)
        if k % 2 == 0:
            out.append(("joints/arm", JointFrame.make(t + 300_000, q, np.zeros(6), np.zeros(6), source="arm",
                                                      seq=k // 2)))
        out.append(("wrench/ft", WrenchFrame.make(t, [5.0, -3.0, 190.0 + k * 0.01, 1.0, 2.0, -0.5], source="ft",
                                                  seq=k)))
        if inputs:
            out.append((MONITOR_INPUT, PipelineInput(t, None, k, "ft", np.zeros(6), q, np.zeros(6), np.zeros(6))))
        if k - 1 in contact:  # an event goes out one sample after its own time
            kind = contact[k - 1]
            te = t - 1_000_000 if kind != "offset" else t
            tp = te if kind != "offset" else T0 + 260 * 1_000_000
            flags = ("ambiguous",) if k - 1 == 240 else ()
            out.append(("events/contact", ContactEvent.make(te, kind, "forearm", on_forearm(tp), [3.0, -4.0, -12.0],
                                                            [0.002, 0.004, 0.003], flags=flags, contact_id=1)))
        if k == 600:
            out.append(("events/contact", ContactEvent.make(t, "onset", "forearm", [0, 0, 0], [0, 0, 0],
                                                            flags=("no_estimate",), contact_id=2)))
    return out


def record(path, sent, scene=SCENE) -> McapRecorder:
    bus = Bus()
    rec = McapRecorder(bus, path, metadata={"scene": {"name": SCENE.name, "path": str(SCENE.path)}}, scene=scene)
    with rec:
        for topic, f in sent:
            bus.publish(topic, f)
        time.sleep(0.1)
    return rec


@pytest.mark.parametrize("inputs", [True, False], ids=["monitor-inputs", "joints-only"])
def test_the_contact_markers_compose_onto_the_events_points(tmp_path, inputs):
    path = tmp_path / "run.mcap"
    rec = record(path, frames(inputs=inputs))
    assert rec.foxglove_errors == 0 and rec.drops == 0
    fox = read_foxglove(path)  # every message valid against Foxglove's schema in the file
    assert set(fox.schemas) == FOXGLOVE_TOPICS
    assert fox.schemas["foxglove/tf"] == "foxglove.FrameTransforms"
    assert {fox.schemas[t] for t in FOXGLOVE_TOPICS - {"foxglove/tf"}} == {"foxglove.SceneUpdate"}
    placed = contact_markers_in_base(fox)
    assert [ev["kind"] for ev, _, _ in placed] == ["onset", "update", "update", "update", "offset"]
    for ev, centre, ent in placed:
        assert np.linalg.norm(centre - np.array(ev["point"])) < 1e-3, (ev["kind"], centre, ev["point"])
        # the arrow's head on the point
        arrow = ent["arrows"][0]
        link_T_arrow = of_pose(arrow["pose"])
        length = arrow["shaft_length"] + arrow["head_length"]
        head = link_T_arrow[:3, 3] + link_T_arrow[:3, 0] * length
        marker = of_pose(ent["spheres"][0]["pose"])[:3, 3]
        assert np.linalg.norm(head - marker) < 1e-9
        ellipsoid = ent["spheres"][1]["size"]
        assert np.allclose([ellipsoid["x"], ellipsoid["y"], ellipsoid["z"]], 2 * K95_3D * np.array(ev["point_std"]))
        meta = {kv["key"]: kv["value"] for kv in ent["metadata"]}
        assert meta["link"] == "forearm" and meta["flags"] == ",".join(ev["flags"])
        assert ent["lifetime"]["sec"] == 3 and ent["frame_locked"]
    # the offset stays where the last update put it on the link, not where the link went since
    assert np.allclose(placed[-1][1], placed[-2][1], atol=1e-9)
    assert placed[-1][2]["spheres"][0]["pose"] == placed[-2][2]["spheres"][0]["pose"]
    assert rec.foxglove.skipped == {"contact_no_estimate": 1}


def test_the_arrows_point_along_the_force_in_the_base_frame(tmp_path):
    path = tmp_path / "run.mcap"
    record(path, frames(0.4))
    fox = read_foxglove(path)
    for ev, _, ent in contact_markers_in_base(fox):
        if ev["kind"] == "offset":
            continue
        base_T_arrow = fox.pose("forearm", ev["t_host_ns"]) @ of_pose(ent["arrows"][0]["pose"])
        f = np.array(ev["force"])
        assert np.allclose(base_T_arrow[:3, 0], f / np.linalg.norm(f), atol=1e-9)


def test_transforms_and_surfaces_are_where_the_model_has_them(tmp_path):
    path = tmp_path / "run.mcap"
    record(path, frames(0.5))
    fox = read_foxglove(path)
    tfs = fox.messages["foxglove/tf"]
    # decimated to 50 Hz (+ one per contact event with an estimate at its own time): 0.5 s of 1 kHz
    assert 25 <= len(tfs) <= 25 + 5
    stamps = sorted({tf["timestamp"]["sec"] * 10**9 + tf["timestamp"]["nsec"] for m in tfs for tf in m["transforms"]})
    assert len(fox.messages["foxglove/wrench"]) == 25
    assert len(fox.messages["foxglove/arm"]) == 1
    links = {e["frame_id"]: e for e in fox.entities("foxglove/arm")}
    assert set(links) == {s.link for s in ARM.surfaces}
    for t in [t for t in stamps if t % 1_000_000 == 0][::5]:  # the inputs' poses (joints' come 0.3 ms late)
        posed = ARM.posed_surfaces(q_at(t))
        for ps in posed:  # each primitive: its centre, axes and size (MuJoCo's half-sizes doubled)
            kind, size = ps.surface.kind, np.asarray(ps.surface.size)
            box = {"cylinder": ("cylinders", [2 * size[0], 2 * size[0], 2 * size[1]]),
                   "capsule": ("cylinders", [2 * size[0], 2 * size[0], 2 * size[1]]),
                   "ellipsoid": ("spheres", 2 * size[:3]), "sphere": ("spheres", [2 * size[0]] * 3),
                   "box": ("cubes", 2 * size[:3])}[kind]
            base_T_link = fox.pose(ps.surface.link, t)
            assert any(np.allclose(base_T_link @ of_pose(p["pose"]), ps.base_T_geom, atol=1e-9)
                       and np.allclose([p["size"]["x"], p["size"]["y"], p["size"]["z"]], box[1])
                       for p in links[ps.surface.link][box[0]]), (ps.surface.geom, kind)
        assert np.allclose(fox.pose("sensor", t), ARM.base_T_sensor(q_at(t)), atol=1e-9)
    # a capsule is a cylinder and two spheres; the 21 ur5e primitives include 2 capsules and 1 ellipsoid
    kinds = [s.kind for s in ARM.surfaces]
    n = {k: sum(len(e[k]) for e in links.values()) for k in ("cylinders", "spheres", "cubes")}
    assert n == {"cylinders": kinds.count("cylinder") + kinds.count("capsule"),
                 "spheres": 2 * kinds.count("capsule") + kinds.count("ellipsoid") + kinds.count("sphere"),
                 "cubes": kinds.count("box")}
    assert fox.metadata["foxglove"]["root_frame"] == "world" and fox.metadata["foxglove"]["rate_hz"] == "50"
    assert fox.metadata["recorder"]["messages:foxglove/tf"] == str(len(tfs))


def bus_channels(path) -> list[tuple]:
    with open(path, "rb") as f:
        return [(c.topic, s.name, m.log_time, m.publish_time, m.sequence, m.data)
                for s, c, m in make_reader(f).iter_messages(log_time_order=False) if not s.name.startswith("foxglove.")]


def test_the_bus_channels_are_the_same_bytes_with_or_without_the_foxglove_ones(tmp_path):
    sent = frames(0.4)
    record(tmp_path / "with.mcap", sent)
    record(tmp_path / "without.mcap", sent, scene=None)
    with_fox, without = bus_channels(tmp_path / "with.mcap"), bus_channels(tmp_path / "without.mcap")
    assert len(without) == len(sent) and with_fox == without
    got = read_recording(tmp_path / "with.mcap")  # what replay reads: the bus's frames only
    assert got.complete and got.bad_messages == 0 and got.view_messages > 0
    assert [m.topic for m in got.messages] == [t for t, _ in sent]
    assert recorded_scene(got).name == "ur5e"


def test_bad_frames_are_counted_and_the_recording_goes_on(tmp_path):
    path = tmp_path / "bad.mcap"
    sent = frames(0.3, inputs=False)
    t = T0 + 300_000_000
    bad = [  # at a 20 ms boundary, where the view uses the frames (it checks them there)
        ("events/contact", ContactEvent.make(t, "onset", "no_such_link", [0.1, 0, 0], [1.0, 0, 0], contact_id=7)),
        ("events/contact", ContactEvent.make(T0 - 10**9, "onset", "forearm", [0.1, 0, 0], [1.0, 0, 0], contact_id=8)),
        ("joints/arm", JointFrame(t, None, 998, "arm", np.zeros(3), np.zeros(3), np.zeros(3))),  # 3 joints, not 6
        ("joints/arm", JointFrame(t, None, 999, "arm", np.full(6, np.nan), np.zeros(6), np.zeros(6))),
        ("wrench/ft", WrenchFrame(t, None, 999, "ft", np.array([np.inf, 0, 0, 0, 0, 0.0]))),
        (MONITOR_INPUT, PipelineInput(t, None, 999, "ft", np.zeros(6), np.full(6, np.nan), np.zeros(6), np.zeros(6))),
    ]
    later = [(topic, f) for topic, f in frames(0.5, inputs=False)[len(sent):] if topic != "events/contact"]
    rec = record(path, sent + bad + later)
    assert dict(rec.foxglove.skipped) == {"bad_q": 3, "bad_wrench": 1, "contact_unknown_link": 1, "contact_no_pose": 1}
    assert rec.foxglove_errors == 0
    fox = read_foxglove(path)  # still valid: no NaN reached a Foxglove message
    meta = fox.metadata["recorder"]
    assert meta["foxglove_skipped:bad_q"] == "3" and meta["foxglove_errors"] == "0"
    got = read_recording(path)  # the bus's channels keep every frame (the non-finite ones read as bad, as ever)
    assert got.complete and got.bad_messages == 3
    assert len(got.messages) + got.bad_messages == len(sent) + len(bad) + len(later)
    last_tf = max(tf["timestamp"]["sec"] * 10**9 + tf["timestamp"]["nsec"] for m in fox.messages["foxglove/tf"]
                  for tf in m["transforms"])
    assert last_tf > t + 100_000_000  # the arm's transforms went on after the bad frames


def test_a_failing_view_costs_nothing_of_the_bus_channels(tmp_path, monkeypatch):
    path = tmp_path / "broken.mcap"
    bus = Bus()
    rec = McapRecorder(bus, path, scene=SCENE)

    def broken(q):
        raise RuntimeError("kinematics broke")

    monkeypatch.setattr(rec.foxglove.arm, "body_poses", broken)
    sent = frames(0.2)
    with rec:
        for topic, f in sent:
            bus.publish(topic, f)
        time.sleep(0.1)
    assert rec.foxglove_errors > 0
    got = read_recording(path)
    assert got.complete and [m.topic for m in got.messages] == [t for t, _ in sent]
    assert got.metadata["recorder"]["foxglove_error"] == "RuntimeError: kinematics broke"


def test_matrix_of_a_quarter_turn_about_z():  # the checker's own quaternion formula
    m = matrix({"x": 1, "y": 2, "z": 0}, {"x": 0, "y": 0, "z": np.sqrt(0.5), "w": np.sqrt(0.5)})
    assert np.allclose(m @ [1, 0, 0, 1], [1, 3, 0, 1])
