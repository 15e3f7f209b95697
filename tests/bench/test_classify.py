"""Contact classification (issue 39) on stepped worlds: a typical world (another arm than the pipeline's
model), one scripted contact of each kind, through a base F/T sensor's pipeline and the joint signals' (currents
and a flange F/T); the class at the onset (provisional) and at the offset (final); the scripted kinds in the
world's truth; replay reproduces the classes."""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from ftc_hw.bench.classify import RIGHT, judge, run_world
from ftc_hw.bus import EVENTS_CONTACT, ContactEvent
from ftc_hw.model import ArmModel
from ftc_hw.pipeline.classify import ContactClassifier
from ftc_hw.record import schemas
from ftc_hw.record.reader import read_recording
from ftc_hw.record.replay import replay
from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.world import World, with_reality
from ftc_hw.sim_devices.world.contact_kinds import CONTACT_KINDS, plan_contacts
from ftc_hw.sim_devices.world.truth import truth_line, truth_record

pytestmark = pytest.mark.compute  # worlds stepped as fast as they go

RECORDING = Path(__file__).parent.parent / "data" / "recordings" / "dxl-arm-ideal.mcap"


@pytest.mark.parametrize("name", ["dxl-arm", "ur10e"])  # a base F/T sensor's pipeline; currents + a flange F/T
def test_each_scripted_kind_is_classified_right_in_a_typical_world(name):
    scene = load_scene(name)
    run = run_world(scene, with_reality(scene, "typical", seed=3), 7, 1)
    plan, events = run.plan, run.events
    rows = judge(plan, events)
    assert [r["kind"] for r in rows] == list(CONTACT_KINDS)
    for r in rows:
        assert r["reported"], r
        assert (r["contact_class"], r["intent"]) == RIGHT[r["kind"]], r
        p = r["p_quasi_static"] if r["kind"] == "clamping" else 1.0 - r["p_quasi_static"]
        assert p >= 0.8, r
        assert {"held_s", "rise_s", "v_onset_mps"} <= set(r["features"]), r
    # every settled update judged against the body limits, its effective mass beside the true arm's
    assert {m["kind"] for m in run.masses} == set(CONTACT_KINDS)
    assert all(m["mass"] > 0 and m["true"] > 0 for m in run.masses)
    onsets = [e for e in events if e.kind == "onset"]
    # a contact of the arm at rest cannot be told a clamp from a hand at its onset: it says so
    guided = next(e for e in onsets if plan[1].t_start <= e.t_host_ns * 1e-9 <= plan[1].t_end)
    assert guided.intent == "unknown" and 0.2 < guided.p_guidance < 0.8
    assert guided.contact_class == "unknown" and 0.2 < guided.p_quasi_static < 0.8


def test_an_unclassifiable_contact_says_so_with_its_probability():
    c = ContactClassifier()
    c.begin(0)
    # 0.1 s of a force rising on an arm at rest: a hand about to lead it or a fixture it is pressed against
    for k in range(100):
        c.add(k * 1_000_000, 0.1 * k, 0.0)
    out = c.result()
    assert out.contact_class == "unknown" and 0.2 < out.p_quasi_static < 0.8
    assert out.intent == "unknown" and 0.2 < out.p_guidance < 0.8
    assert out.features["rise_s"] == pytest.approx(0.099)
    # a force on an arm moving into it at 0.2 m/s: accidental, said at once; whether the arm will be stopped
    # against something (clamped) only time tells
    c.begin(0)
    for k in range(1, 30):
        c.add(k * 1_000_000, 0.5 * k, -0.2 * 0.5 * k)
    moving = c.result()
    assert moving.intent == "impact" and moving.p_guidance < 0.01
    assert moving.contact_class == "unknown"
    for k in range(30, 200):  # released at 0.2 s
        c.add(k * 1_000_000, 15.0 if k < 150 else 0.0, -0.2 * 15.0 if k < 150 else 0.0)
    assert c.result(released=True).contact_class == "transient"


def test_the_truth_says_each_scripted_contact_s_kind_the_same_both_ways():
    scene = load_scene("ur5e")
    setup, plan = plan_contacts(scene, ArmModel(scene), np.random.default_rng(1), ("guidance",), 1)
    world = World(scene, setup, seed=0)
    seen = set()
    s = world.state
    while s.t < (plan[0].t_start + plan[0].t_end) / 2:  # to the middle of the hand's push
        s = world.step()
        seen |= {c.label for c in s.contacts}
    line = truth_line(s, {})
    assert json.loads(line) == json.loads(json.dumps(truth_record(s)))
    assert seen == {"guidance"}
    assert [c.get("class") for c in json.loads(line)["contacts"]] == ["guidance"]


def test_replay_reproduces_the_classes_a_recording_holds():
    rec = read_recording(RECORDING)
    first = replay(rec)
    classified = [e for e in first.events if isinstance(e, ContactEvent)]
    assert classified and all(e.contact_class for e in classified)
    # the recording as a run of today's would hold it: its events with their classes, through the MCAP schemas
    events = iter(e for e in first.events if isinstance(e, ContactEvent))
    messages = []
    for m in rec.messages:
        if m.topic == EVENTS_CONTACT:
            name, data = schemas.encode(next(events))
            m = dataclasses.replace(m, frame=schemas.decode(name, data))
        messages.append(m)
    again = replay(dataclasses.replace(rec, messages=messages))
    assert again.identical, again.first_difference()
    assert [e.contact_class for e in again.recorded if isinstance(e, ContactEvent)] == \
        [e.contact_class for e in classified]


def test_a_hand_leads_the_arm_only_where_its_joints_can_move_the_point_along_the_push():
    """A push the joints cannot yield to (radially on leng2016's first link, along a joint's axis) holds the arm
    still like a clamp: the scripted guidance is planned only where the planned joint motion moves the touched
    point along the push (at least 90 % of it)."""
    scene = load_scene("leng2016")
    model = ArmModel(scene)
    setup, plan = plan_contacts(scene, model, np.random.default_rng(3), ("guidance",), 6)
    home = np.asarray(scene.robot.home, dtype=float)
    for probe, dq in zip(setup.probes, setup.trajectory.dq, strict=True):
        b_T_l = model.kinematics(home)[probe.link]
        point = b_T_l[:3, :3] @ probe.point_link + b_T_l[:3, 3]
        assert probe.direction @ model.jacobian(home, probe.link, point) @ dq >= 0.9
