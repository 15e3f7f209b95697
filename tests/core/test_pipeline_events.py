"""Contact events (ftc_hw.pipeline.events.contact_event): an estimate the event cannot carry (no link, or an infinite
uncertainty) still gives its event, flagged ``no_estimate``, instead of losing it (an onset among them)."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from ftc_hw.pipeline.events import contact_event

pytestmark = pytest.mark.realtime  # against the wall clock: ./run-tests runs it alone, after the others

event = contact_event


def estimate(link, std, contact=True):
    return SimpleNamespace(contact=contact, link=link, point=np.array([0.1, 0.2, 0.3]),
                           force=np.array([0.0, 0.0, -5.0]), point_std=np.asarray(std, dtype=float),
                           flags=("grazing",))


DET = 0.9  # the detection probability


def test_a_good_estimate_is_carried_as_it_is():
    ev = event(7, "onset", estimate("link3", [0.001, 0.002, 0.003]), DET)
    assert ev.link == "link3" and ev.point.tolist() == [0.1, 0.2, 0.3] and ev.flags == ("grazing",)


def test_an_infinite_uncertainty_gives_a_flagged_event():
    ev = event(7, "update", estimate("link3", [np.nan, np.inf, np.inf]), DET)
    assert ev.kind == "update" and ev.t_host_ns == 7 and ev.link == "link3"
    assert not ev.point.any() and not ev.point_std.any() and ev.flags == ("grazing", "no_estimate")
    assert ev.probability == 0.9


def test_a_point_less_certain_than_its_link_is_big_is_flagged_uncertain():
    reach = {"link3": 0.05}
    # norm of the standard deviations 0.049 m: within the link's 0.05 m
    ev = event(7, "onset", estimate("link3", [0.03, 0.03, 0.0245]), DET, reach=reach)
    assert ev.flags == ("grazing",)
    ev = event(7, "onset", estimate("link3", [0.03, 0.03, 0.03]), DET, reach=reach)
    assert ev.flags == ("grazing", "uncertain") and ev.point.tolist() == [0.1, 0.2, 0.3]  # carried, flagged
    # a track's point is judged by the track's own uncertainty
    track = SimpleNamespace(link="link3", point_and_std=lambda: (np.zeros(3), np.full(3, 0.001)))
    ev = event(7, "update", estimate("link3", [0.3, 0.3, 0.3]), DET, track, reach)
    assert ev.flags == ("grazing",)
    track = SimpleNamespace(link="link3", point_and_std=lambda: (np.zeros(3), np.full(3, 0.04)))
    assert "uncertain" in event(7, "update", estimate("link3", [0.001] * 3), DET, track, reach).flags


def test_the_link_reach_holds_every_primitive_of_the_link():
    from ftc_hw.model import ArmModel
    from ftc_hw.model.arm import link_reach
    from ftc_hw.model.sampling import sample_surface_points
    from ftc_hw.scene import load_scene

    for name in ("ur5e", "dxl-arm", "leng2016"):
        model = ArmModel(load_scene(name))
        q = np.array(model.scene.robot.home, dtype=float)
        reach = link_reach(model)
        links = model.kinematics(q)
        far = dict.fromkeys(reach, 0.0)
        for sp in sample_surface_points(model, q, 3000, np.random.default_rng(0)):
            far[sp.link] = max(far[sp.link], float(np.linalg.norm(sp.point - links[sp.link][:3, 3])))
        for link, r in reach.items():
            assert 0.5 * r < far[link] <= r + 1e-9, (name, link, far[link], r)


def test_an_estimate_without_a_link_gives_a_flagged_event():
    ev = event(9, "onset", estimate(None, [0.0, 0.0, 0.0], contact=False), DET)
    assert ev.kind == "onset" and ev.link == "unknown" and "no_estimate" in ev.flags


def test_a_contact_is_held_while_the_model_error_blinds_the_offset_test():
    """Braking hard (a reflex stop) makes the compensation's own uncertainty as large as a contact:
    such samples do not count toward an offset, so the contact does not end and start again; once
    the model error is back to small, a small wrench ends the contact as before."""
    from ftc_hw.detection import ContactDetector

    det = ContactDetector(np.eye(6) * 0.01, n_on=2, n_off=5)
    push = np.array([0.0, 0.0, 20.0, 0.0, 0.0, 0.0])
    assert det.update(0, push).change is None and det.update(1, push).change == "onset"
    blinding = np.array([[0.0, 0.0, 50.0, 0.0, 0.0, 0.0]])  # 50 N of possible model error
    for t in range(2, 40):
        d = det.update(t, np.zeros(6), blinding)
        assert d.blind and d.active and d.change is None
    changes = [det.update(t, np.zeros(6)).change for t in range(40, 45)]
    assert changes == [None, None, None, None, "offset"]


def test_a_new_pipeline_has_its_compiled_kernels_loaded():
    """numba loads a kernel from its cache on the first call (tens of ms): a fresh pipeline has made
    that call, so its first contact (and the reflex stop) does not wait for it. In a fresh process."""
    import subprocess
    import sys

    code = ("from ftc_hw.scene import load_scene\n"
            "from ftc_hw.pipeline import ContactPipeline\n"
            "from ftc_hw.detection import kernels as D\n"
            "from ftc_hw.solver import kernels as K\n"
            "from ftc_hw.tracking import fuse_point, link_pose, report\n"
            "from ftc_hw.compensation.residuals import _external_torques\n"
            "ContactPipeline(load_scene('ur5e'))\n"
            "print(all(len(f.signatures) > 0 for f in (D.mahalanobis2, D.quad_sum, D.window_change,"
            " K.solve_frame_q, K.weight_stack, fuse_point, link_pose, report, _external_torques)))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "True"


def test_a_model_error_that_stays_large_blinds_the_offset_test_for_a_bounded_time():
    """A model identified from too little motion can carry an error as large as an onset all the while
    the arm moves: the contact must still end (after ``max_blind_s``), or it would hide every later one."""
    from ftc_hw.detection import ContactDetector

    det = ContactDetector(np.eye(6) * 0.01, n_on=2, n_off=5, max_blind_s=0.5)
    push = np.array([0.0, 0.0, 20.0, 0.0, 0.0, 0.0])
    blinding = np.array([[0.0, 0.0, 50.0, 0.0, 0.0, 0.0]])
    ms = 1_000_000
    for contact in range(2):
        t0 = contact * 2000 * ms
        assert det.update(t0, push).change is None and det.update(t0 + ms, push).change == "onset"
        changes = {k: det.update(t0 + k * ms, np.zeros(6), blinding) for k in range(2, 1000)}
        blind = [k for k, d in changes.items() if d.blind]
        assert blind == list(range(2, 502)), (contact, blind[:3], blind[-3:])  # 0.5 s from its first blind sample
        ended = [k for k, d in changes.items() if d.change == "offset"]
        assert ended == [506], (contact, ended)  # then five small samples
