"""ContactTrack: a contact's point fused over its frames, in the touched link's frame, with an
uncertainty that stays honest (the filter's own plus the share no fusion removes)."""
from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

from ftc_hw.model import ArmModel, Contact
from ftc_hw.pipeline import ContactPipeline
from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.world.scenarios import _ray_to_surface
from ftc_hw.tracking import ContactTrack
from tests.conftest import settings

SCENE = load_scene("ur5e")
MODEL = ArmModel(SCENE)
HOME = np.array(SCENE.robot.home, dtype=float)
LINK = "wrist_3"
MS = 1_000_000


def tangent_cov(sigma: float, normal=(0.0, 0.0, 1.0)) -> np.ndarray:
    """A rank-2 point covariance (as the solver gives: on the surface), sigma per in-plane axis."""
    n = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    return sigma ** 2 * (np.eye(3) - np.outer(n, n))


def est(point, cov3, link=LINK, flags=(), contact=True):
    cov = np.zeros((6, 6))
    cov[:3, :3] = cov3
    return SimpleNamespace(contact=contact, link=link, point=np.asarray(point, dtype=float), cov=cov, flags=flags)


def on_link(q, local) -> np.ndarray:
    b_T_l = MODEL.kinematics(q)[LINK]
    return b_T_l[:3, :3] @ np.asarray(local) + b_T_l[:3, 3]


def test_a_fixed_point_is_fused_and_its_uncertainty_is_honest():
    """Frames of a fixed point with independent noise: the fused error shrinks about as 1/sqrt(n)
    and the reported uncertainty matches it (no bias, no chain share: the filter alone)."""
    rng = np.random.default_rng(1)
    truth = on_link(HOME, [0.01, 0.0, 0.02])
    sigma, n, runs = 0.01, 100, 200
    cov = tangent_cov(sigma)
    errs, stds = [], []
    for _ in range(runs):
        tr = ContactTrack(MODEL, slide=1e-6, chain_ratio=0.0)
        for k in range(n):
            noise = rng.normal(size=3) * sigma
            noise[2] = 0.0
            assert tr.update(k * MS, est(truth + noise, cov), HOME)
        errs.append(tr.point - truth)
        stds.append(tr.point_std)
    errs, stds = np.array(errs), np.array(stds)
    rms = np.sqrt(np.mean(errs[:, :2] ** 2))
    assert rms == pytest.approx(sigma / np.sqrt(n), rel=0.15)
    assert np.mean(stds[:, :2]) == pytest.approx(sigma / np.sqrt(n), rel=0.05)
    assert tr.fused == n and tr.rejected == 0


def test_the_point_is_held_in_the_link_frame_while_the_arm_moves():
    track = ContactTrack(MODEL, slide=1e-6)
    local = [0.0, 0.03, 0.01]
    cov = tangent_cov(0.002)
    for k in range(20):
        q = HOME + 0.02 * k  # every joint turns: the point moves through the base frame
        assert track.update(k * MS, est(on_link(q, local), cov), q)
    assert np.linalg.norm(track.point - on_link(q, local)) < 1e-9


def test_an_outlier_is_left_out_and_a_move_restarts_the_track():
    track = ContactTrack(MODEL, restart_after=3)
    p0 = on_link(HOME, [0.0, 0.0, 0.0])
    cov = tangent_cov(0.001)
    for k in range(10):
        track.update(k * MS, est(p0, cov), HOME)
    far = p0 + np.array([0.05, 0.0, 0.0])
    assert not track.update(10 * MS, est(far, cov), HOME)  # one estimate 50 sigma off
    assert track.rejected == 1 and np.linalg.norm(track.point - p0) < 1e-6
    assert track.update(11 * MS, est(p0, cov), HOME)  # agreeing again: the count starts over
    assert not track.update(12 * MS, est(far, cov), HOME)
    assert not track.update(13 * MS, est(far, cov), HOME)
    assert track.update(14 * MS, est(far, cov), HOME)  # third in a row: the contact moved
    assert track.restarts == 1 and np.linalg.norm(track.point - far) < 1e-9 and track.fused == 1


def test_estimates_it_cannot_trust_stay_out():
    track = ContactTrack(MODEL, restart_after=3)
    p0 = on_link(HOME, [0.0, 0.0, 0.0])
    cov = tangent_cov(0.001)
    assert not track.update(0, est(p0, cov, flags=("ambiguous",)), HOME)
    assert not track.update(0, est(p0, cov, flags=("low_force",), contact=False), HOME)
    assert not track.update(0, est(p0 * np.nan, cov), HOME)
    assert not track.update(0, est(p0, cov, flags=("grazing",)), HOME)  # a track starts from a clean one
    assert not track.active
    assert track.update(0, est(p0, cov), HOME)
    assert track.update(MS, est(p0, cov, flags=("grazing",)), HOME)  # then grazing ones are fused
    assert not track.update(2 * MS, est(p0, cov, flags=("ambiguous",)), HOME)  # agrees: neither fused nor a miss
    assert not track.update(3 * MS, est(p0, cov, link="forearm"), HOME)  # another link: a miss
    assert track.link == LINK and track.rejected == 1 and track.fused == 2
    with pytest.raises(ValueError):
        ContactTrack(MODEL, p_gate=0.5)


def test_flagged_estimates_that_disagree_end_the_track():
    """A track whose estimates keep disagreeing, with nothing clean to restart from, ends: the
    events then carry each frame's own (flagged) estimate instead of a point nobody confirms."""
    track = ContactTrack(MODEL, restart_after=3)
    p0 = on_link(HOME, [0.0, 0.0, 0.0])
    cov = tangent_cov(0.001)
    track.update(0, est(p0, cov), HOME)
    far = est(p0 + np.array([0.05, 0.0, 0.0]), cov, flags=("ambiguous",))
    for k in range(1, 3):
        assert not track.update(k * MS, far, HOME) and track.active
    assert not track.update(3 * MS, far, HOME)
    assert not track.active


def test_a_bias_error_is_never_averaged_down():
    """A tare over n samples leaves 1/n of the noise's variance in every frame: however many frames
    are fused, the reported variance keeps that share of one frame's."""
    p0 = on_link(HOME, [0.0, 0.0, 0.0])
    cov = tangent_cov(0.01)
    track = ContactTrack(MODEL, slide=1e-6, chain_ratio=0.0)
    track.set_bias(1 / 100)
    for k in range(2000):
        track.update(k * MS, est(p0, cov), HOME)
    var = float(np.sum(track.point_std ** 2))
    frame = float(np.trace(cov))
    assert var == pytest.approx(frame / 100 + frame / 2000, rel=0.1)
    track.set_bias(0.0)
    track.reset()
    for k in range(2000):
        track.update(k * MS, est(p0, cov), HOME)
    assert float(np.sum(track.point_std ** 2)) == pytest.approx(frame / 2000, rel=0.1)
    with pytest.raises(ValueError):
        track.set_bias(-1.0)


def held_contact_events(track_slide):
    """A 30 N push held on wrist_3 for 0.3 s at 1 kHz with the scene's sensor noise, through the
    pipeline: its events, and the true point."""
    rng = np.random.default_rng(3)
    # what fusing frames gains, alone: no systematic share (surface tolerance, sensor accuracy)
    exact = dataclasses.replace(SCENE, robot=dataclasses.replace(SCENE.robot, surface_tolerance=0.0),
                                sensor=dataclasses.replace(SCENE.sensor, accuracy=0.0))
    pipe = ContactPipeline(exact, settings(level="bias", bias=np.zeros(6), use_currents=False, track_slide=track_slide,
                           surface="primitives"))  # the truth is on the primitives: the track alone
    surf = next(s for s in MODEL.surfaces if s.link == LINK)
    b_T_l = MODEL.kinematics(HOME)[LINK]
    centre = (b_T_l @ surf.link_T_geom)[:3, 3]
    # a point on the surface, cast at from outside along base -y (a line that crosses no other link)
    inward = np.array([0.0, -1.0, 0.0])
    point = _ray_to_surface(MODEL, HOME, centre - 0.3 * inward, inward)
    force = 30.0 * inward
    clean = MODEL.predicted_wrench(HOME, level="bias", contacts=[Contact(LINK, point, force)])
    std = np.sqrt(np.diag(SCENE.sensor.noise_cov))
    events = []
    for k in range(400):
        raw = (clean if 20 <= k < 320 else np.zeros(6)) + rng.normal(size=6) * std
        events += pipe.process(k * MS, raw, HOME).events
    return events, point


def test_the_pipelines_events_carry_the_fused_point():
    fused, point = held_contact_events(0.01)
    single, _ = held_contact_events(None)
    kinds = [e.kind for e in fused]
    assert kinds[0] == "onset" and kinds[-1] == "offset" and kinds.count("onset") == 1
    fused = [e for e in fused if e.kind == "update" and not e.flags]  # (the release's are flagged low_force)
    single = [e for e in single if e.kind == "update" and not e.flags]
    assert len(fused) >= 12 and len(single) >= 12
    err = np.array([np.linalg.norm(e.point - point) for e in fused])
    err1 = np.array([np.linalg.norm(e.point - point) for e in single])
    std = np.array([np.linalg.norm(e.point_std) for e in fused])
    std1 = np.array([np.linalg.norm(e.point_std) for e in single])
    # fused: several times better than one frame, and they say so
    assert np.sqrt(np.mean(err ** 2)) < 0.5 * np.sqrt(np.mean(err1 ** 2))
    assert np.median(std) < 0.5 * np.median(std1)
    # and the uncertainty they report covers their error
    assert np.sqrt(np.mean((err / std) ** 2)) < 1.5


def test_the_solvers_body_poses_are_mujocos():
    """The track reads the link's pose from the solver's own kinematics of the frame it just solved
    (or computes it for another q): the same poses as MuJoCo's."""
    from ftc_hw.solver import ContactSolver

    solver = ContactSolver(MODEL)
    for q, solve in ((HOME + 0.1, True), (HOME - 0.2, False)):
        if solve:
            solver.solve(np.array([0.0, 0.0, 10.0, 0.0, 0.0, 0.0]), q)
        xpos, xquat = (a.copy() for a in solver.body_poses(q))
        ref_pos, ref_quat = (a.copy() for a in MODEL.body_poses(q))
        assert np.allclose(xpos, ref_pos, atol=1e-12)
        assert np.allclose(np.abs(np.sum(xquat * ref_quat, axis=1)), 1.0, atol=1e-12)  # q and -q alike


def test_the_onset_rests_on_the_sample_before_it_too():
    """The onset goes out at the second sample above the threshold: the first one, already above,
    is fused too, so the onset's point rests on two frames (on the primitives the wrench was made on)."""
    pipe = ContactPipeline(SCENE, settings(level="bias", bias=np.zeros(6), use_currents=False, surface="primitives"))
    surf = next(s for s in MODEL.surfaces if s.link == LINK)
    centre = (MODEL.kinematics(HOME)[LINK] @ surf.link_T_geom)[:3, 3]
    inward = np.array([0.0, -1.0, 0.0])
    point = _ray_to_surface(MODEL, HOME, centre - 0.3 * inward, inward)
    clean = MODEL.predicted_wrench(HOME, level="bias", contacts=[Contact(LINK, point, 30.0 * inward)])
    for k in range(20):
        assert not pipe.process(k * MS, np.zeros(6), HOME).events
    assert not pipe.process(20 * MS, clean, HOME).events  # above the threshold: one sample is no onset
    (onset,) = pipe.process(21 * MS, clean, HOME).events
    assert onset.kind == "onset" and onset.t_host_ns == 20 * MS
    assert pipe.events.track.fused == 2 and np.linalg.norm(onset.point - point) < 1e-9


def test_events_carry_what_fusing_cannot_average_away():
    """The surface tolerance and the sensor's accuracy on the contact's own wrench widen every
    event's point uncertainty (never shrinking with frames): with both, the held push's events
    report more than the fused frames alone, and at least the surface tolerance on every axis."""
    fused, _ = held_contact_events(0.01)
    rng = np.random.default_rng(3)
    pipe = ContactPipeline(SCENE, settings(level="bias", bias=np.zeros(6), use_currents=False, track_slide=0.01,
                           surface="primitives"))
    surf = next(s for s in MODEL.surfaces if s.link == LINK)
    centre = (MODEL.kinematics(HOME)[LINK] @ surf.link_T_geom)[:3, 3]
    inward = np.array([0.0, -1.0, 0.0])
    point = _ray_to_surface(MODEL, HOME, centre - 0.3 * inward, inward)
    clean = MODEL.predicted_wrench(HOME, level="bias", contacts=[Contact(LINK, point, 30.0 * inward)])
    std = np.sqrt(np.diag(SCENE.sensor.noise_cov))
    events = []
    for k in range(400):
        raw = (clean if 20 <= k < 320 else np.zeros(6)) + rng.normal(size=6) * std
        events += pipe.process(k * MS, raw, HOME).events
    wide = [e for e in events if e.kind == "update" and not e.flags]
    narrow = [e for e in fused if e.kind == "update" and not e.flags]
    assert wide and narrow
    assert all(np.all(e.point_std >= SCENE.robot.surface_tolerance) for e in wide)
    # 0.5 % of a 30 N push 0.6 m out, and its crosstalk: millimetres, well above the fused noise
    assert np.median([np.linalg.norm(e.point_std) for e in wide]) > 2 * np.median(
        [np.linalg.norm(e.point_std) for e in narrow])
