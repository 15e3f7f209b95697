"""The physics world: with noise off its sensor reading equals the model's prediction for the true contacts."""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from ftc_hw.model import ArmModel, Contact, sample_rate_hz
from ftc_hw.scene import builtin_names, load_scene
from ftc_hw.sim_devices.world import SCENARIOS, World, build_scenario, truth_record
from ftc_hw.sim_devices.world.scenarios import SWEEP_REST_S
from ftc_hw.sim_devices.world.sensor_model import FTSensorModel
from ftc_hw.sim_devices.world.truth import truth_line

pytestmark = pytest.mark.compute  # computes only (nothing timed): runs with the others on every core


def _world(scene_name, scenario, duration, seed=3, noise=False):
    scene = load_scene(scene_name)
    model = ArmModel(scene)
    setup = build_scenario(scenario, scene, model, seed, duration)
    return scene, setup, World(scene, setup, seed=seed, noise=noise)


@pytest.mark.parametrize("scene_name", ["leng2016", "ur5e", "dxl-arm"])
@pytest.mark.parametrize("scenario", ["static-pokes", "sweep-with-collision", "payload-poses"])
def test_noise_free_reading_equals_model_prediction(scene_name, scenario):
    duration = {"static-pokes": 1.3, "sweep-with-collision": 2.0, "payload-poses": 2.0}[scenario]
    scene, setup, world = _world(scene_name, scenario, duration)
    model = ArmModel(scene, setup.payload)
    in_contact = 0
    worst = 0.0
    for state, reading in world.run(duration):
        contacts = [Contact(c.link, c.point, c.force) for c in state.contacts]
        in_contact += bool(contacts)
        predicted = model.predicted_wrench(state.q, state.qd, state.qdd, "dynamics", contacts)
        worst = max(worst, float(np.abs(state.wrench - predicted).max()))
        # the device reading adds exactly the scene's bias (and drift) when noise is off
        expected = np.clip(predicted + scene.sensor.bias + scene.sensor.drift_per_s * state.t,
                           -scene.sensor.range, scene.sensor.range)
        if not np.any(scene.sensor.quantization > 0):
            np.testing.assert_allclose(reading.wrench, expected, atol=1e-8)
    scale = max(1.0, float(np.abs(state.wrench).max()))
    # A coupling (dxl-arm's gripper) is a soft equality constraint in the world: its fingers' accelerations
    # differ by up to ~0.02 m/s^2, which their 1 g each turns into ~1e-5 N the 5-joint model cannot hold.
    assert worst <= (1e-5 if scene.robot.couplings else 1e-9) * scale, worst
    if scenario != "payload-poses":
        assert in_contact > 0, "the scenario produced no contact"


def test_probe_truth_is_on_the_link_surface_and_pushes_in():
    scene, setup, world = _world("leng2016", "static-pokes", 1.0)
    assert setup.probes
    model = ArmModel(scene)
    for state, _ in world.run(1.0):
        for c in state.contacts:
            links = model.kinematics(state.q)
            local = np.linalg.inv(links[c.link]) @ np.append(c.point, 1.0)
            probe = next(p for p in setup.probes if p.link == c.link and np.allclose(p.point_link, local[:3]))
            assert probe.magnitude_at(state.t) == pytest.approx(np.linalg.norm(c.force))


def test_same_seed_same_run_different_seed_different_run():
    a = [r.wrench for _, r in _world("leng2016", "static-pokes", 0.5, seed=7, noise=True)[2].run(0.5)]
    b = [r.wrench for _, r in _world("leng2016", "static-pokes", 0.5, seed=7, noise=True)[2].run(0.5)]
    c = [r.wrench for _, r in _world("leng2016", "static-pokes", 0.5, seed=8, noise=True)[2].run(0.5)]
    assert np.array_equal(np.array(a), np.array(b))
    assert not np.array_equal(np.array(a), np.array(c))


def test_sensor_model_noise_quantization_saturation():
    scene = load_scene("dxl-arm")
    spec = scene.sensor
    rng = np.random.default_rng(0)
    model = FTSensorModel(spec, rng, noise=True)
    clean = np.zeros(6)
    readings = np.array([model.read(clean, 0.0).wrench for _ in range(4000)])
    lsb = np.where(spec.quantization > 0, spec.quantization, 1.0)
    if np.any(spec.quantization > 0):
        steps = readings / lsb
        assert np.allclose(steps[:, spec.quantization > 0], np.round(steps[:, spec.quantization > 0]), atol=1e-9)
    tolerance = 4 * np.sqrt(np.diag(spec.noise_cov) / 4000) + spec.quantization
    assert np.all(np.abs(readings.mean(axis=0) - spec.bias) <= tolerance)
    np.testing.assert_allclose(readings.std(axis=0), np.sqrt(np.diag(spec.noise_cov)), rtol=0.1)
    big = model.read(spec.range * 2, 0.0)
    assert big.saturated.all()
    np.testing.assert_allclose(big.wrench, spec.range)


def test_truth_record_fields():
    _, _, world = _world("leng2016", "static-pokes", 0.5)
    records = [json.loads(json.dumps(truth_record(s))) for s, _ in world.run(0.5)]
    touched = [r for r in records if r["contact"]]
    free = [r for r in records if not r["contact"]]
    assert touched and free
    for r in touched:
        assert isinstance(r["t"], float) and r["link"] in ("link1", "link2", "link3")
        assert len(r["point"]) == 3 and len(r["force"]) == 3
    assert all(r["link"] is None for r in free)


def test_truth_line_is_what_json_writes():
    """The world's fast truth line is byte for byte json.dumps of the record: contact-free and probed
    samples, two contacts (sorted by force), and the fields json spells its own way (NaN, Infinity)."""
    _, _, world = _world("leng2016", "static-pokes", 0.4)
    states = [s for s, _ in world.run(0.4)]
    touched = [s for s in states if s.contacts]
    assert touched and len(touched) < len(states)
    c = touched[0].contacts[0]
    stronger = dataclasses.replace(c, link="link3", force=3.0 * c.force, source="obstacle")
    states.append(dataclasses.replace(touched[0], contacts=(c, stronger)))
    states.append(dataclasses.replace(touched[0], q=np.array([np.nan, np.inf, -np.inf, 0.0, -0.0, 1e-300])))
    for i, s in enumerate(states):
        fields = {"t": round(s.t - 0.125, 9), "t_world": round(s.t, 9), "t_host_ns": 10**15 + i, "t_due_ns": i}
        rec = truth_record(s)
        rec.update(fields)
        assert truth_line(s, fields) == json.dumps(rec, separators=(",", ":")) + "\n"
        assert truth_line(s, {}) == json.dumps(truth_record(s), separators=(",", ":")) + "\n"


def test_halt_stops_the_arm():
    scene, _, world = _world("leng2016", "sweep", 1.0)
    for _ in world.run(0.5):
        pass
    world.halt()
    for _ in world.run(0.5):
        pass
    assert np.abs(world.state.qd).max() < 1e-3


# what each scenario puts in the world besides its motion (its description says so)
SCRIPTED = {"hold": (), "static-pokes": ("probes",), "static-presses": ("probes",), "sweep": (),
            "sweep-with-collision": ("obstacles",), "excitation": (), "payload-poses": ("payload",),
            "clamping": ("obstacles",), "guidance": ("probes",),
            "impacts": ("obstacles",), "contact-kinds": ("probes", "obstacles")}
LONGER = {"contact-kinds": 15.0}  # s: one contact of each kind takes longer than the others' 5 s


@pytest.mark.parametrize("scene_name", builtin_names())
def test_every_scenario_builds_for_every_scene(scene_name):
    """Each scenario's world starts where its trajectory says, within the joint limits, holds what its
    description says (probes, an obstacle, a payload) and nothing else, steps to finite states with no
    contact before its first scripted one, and a probe presses where and as hard as it is scripted."""
    assert set(SCRIPTED) == set(SCENARIOS)
    scene = load_scene(scene_name)
    model = ArmModel(scene)
    lo, hi = model.joint_limits()
    touchable = {t.link for t in scene.touchable}
    period = 1.0 / sample_rate_hz(scene)
    for name in SCENARIOS:
        duration = LONGER.get(name, 5.0)
        setup = build_scenario(name, scene, model, 0, duration)
        held = {"probes": bool(setup.probes), "obstacles": bool(setup.obstacles), "payload": setup.payload is not None}
        assert {k for k, v in held.items() if v} == set(SCRIPTED[name]), (name, held)
        for t in np.linspace(0.0, duration, 51):
            q_ref = np.asarray(setup.trajectory.reference(t)[0])
            assert q_ref.shape == (scene.n_joints,) and np.all((q_ref >= lo - 1e-9) & (q_ref <= hi + 1e-9)), (name, t)
        for probe in setup.probes:  # on a touchable link, pushing, and over before the run ends
            assert probe.link in touchable and probe.magnitude > 0.0, (name, probe)
            assert np.linalg.norm(probe.direction) == pytest.approx(1.0), (name, probe)
            assert 0.0 < probe.t_start < probe.t_end < duration, (name, probe)
        for obstacle in setup.obstacles:
            assert obstacle.radius > 0.0 and obstacle.stiffness > 0.0 and obstacle.until_s < duration, (name, obstacle)
        if setup.payload is not None:
            assert setup.payload.mass == pytest.approx(0.5), name
        world = World(scene, setup, seed=0)
        q0 = np.asarray(setup.trajectory.reference(0.0)[0])
        assert np.abs(world.state.q - q0).max() < 1e-3, name  # it starts where the scenario does
        first = min([p.t_start for p in setup.probes] + [SWEEP_REST_S if setup.obstacles else duration])
        probe = setup.probes[0] if setup.probes else None
        plateau = None if probe is None else probe.t_start + probe.ramp_s + 0.5 * probe.hold_s
        seen = False
        t_prev = world.state.t
        for state, reading in world.run(plateau + 2 * period if plateau is not None else 0.2):
            assert state.t == pytest.approx(t_prev + period), name
            t_prev = state.t
            assert (reading is None) == (scene.sensor is None) == (state.wrench is None), name
            assert (state.tau_j is None) == (scene.joint_torque is None), name
            for v in (state.q, state.qd, state.qdd, state.tau, state.current,
                      *((state.wrench, reading.wrench) if reading is not None else ()),
                      *((state.tau_j,) if state.tau_j is not None else ())):
                assert np.all(np.isfinite(v)), (name, state.t)
            if state.t < first:
                assert not state.contacts, (name, state.t, state.contacts)
            if plateau is not None and abs(state.t - plateau) < 0.5 * period:
                pressed = [c for c in state.contacts if c.source == "probe"]
                assert len(pressed) == 1 and pressed[0].link == probe.link, (name, state.contacts)
                assert pressed[0].force == pytest.approx(probe.magnitude * probe.direction), name
                seen = True
        assert seen or probe is None, name


def _contact_spans(world, seconds, merge_gap_s=0.05):
    """Contact spans; runs less than ``merge_gap_s`` apart are one (a contact's end may chatter for a
    sample as the compliant obstacle lets go: the monitor's evaluation merges them the same way)."""
    spans, start = [], None
    for state, _ in world.run(seconds):
        if state.contacts and start is None:
            start = spans.pop()[0] if spans and state.t - spans[-1][1] < merge_gap_s else state.t
        elif not state.contacts and start is not None:
            spans.append((start, state.t))
            start = None
    return spans, start


@pytest.mark.parametrize("planned, whole", [(6.9, 1), (8.0, 2)])
def test_the_obstacle_meets_only_the_swings_that_end_within_the_planned_run(planned, whole):
    # the second swing's contact ends at about 6.8 s: a 6.9 s run would cut it, an 8 s run holds it
    scene, setup, world = _world("dxl-arm", "sweep-with-collision", planned)
    spans, open_at_end = _contact_spans(world, 10.5)  # past the third swing's contact (9.7-10.8 s)
    assert open_at_end is None, open_at_end
    assert len(spans) == whole, spans
    assert all(end < planned for _, end in spans), spans
    assert all(end - start > 0.8 for start, end in spans), spans  # each a whole swing's contact


def test_an_obstacle_is_not_withdrawn_while_it_touches_the_arm():
    scene, setup, world = _world("dxl-arm", "sweep-with-collision", 4.0)
    assert setup.obstacles[0].until_s < 5.0
    for _ in world.run(2.3):
        pass
    assert world.state.contacts
    world.halt()  # held against the obstacle past the time it was due to go
    for state, _ in world.run(2.7):
        assert state.contacts, state.t
