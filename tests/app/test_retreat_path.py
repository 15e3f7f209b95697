"""The retreat's joint path (``ftc_hw.app.monitor.retreat``), on the models alone: the touched point goes back
along the contact's force by the configured distance on a straight line, and so does every point the contact
may be at; every setpoint keeps the joints within the scene's speed and acceleration limits and the model's
joint ranges, the path ends within the time limit, and a retreat that cannot be planned says why."""
from __future__ import annotations

import numpy as np
import pytest

from ftc_hw.app.monitor.config import RetreatSettings
from ftc_hw.app.monitor.retreat import RetreatError, plan_retreat, point_at, retreat_direction
from ftc_hw.app.monitor.retreat_region import CHI2_3DOF_95, SurfaceSamples
from ftc_hw.model import ArmModel
from ftc_hw.model.sampling import sample_surface_points
from ftc_hw.scene import load_scene

pytestmark = pytest.mark.compute

PERIOD_S = 0.002


@pytest.fixture(scope="module", params=["ur5e", "dxl-arm"])
def arm(request):
    scene = load_scene(request.param)
    return scene, ArmModel(scene)


def _contacts(model: ArmModel, q: np.ndarray, rng: np.random.Generator, n: int):
    """``n`` points near the touchable links' primitives' centres, of links two joints or more move, each
    pushed in a direction its joints can move it (the Jacobian of random joint velocities). A shoulder's
    point near the pan axis cannot follow a 3 cm line: ``test_an_unreachable_line_is_reported``."""
    out = []
    links = model.kinematics(q)
    movable = [s for s in model.surfaces if model.moving_joints(s.link).sum() >= 2]
    for s in rng.choice(movable, size=n):
        b_T_g = links[s.link] @ s.link_T_geom
        point = b_T_g[:3, 3] + rng.normal(0.0, 0.01, 3)
        force = model.jacobian(q, s.link, point) @ rng.normal(0.0, 1.0, model.n_joints)
        out.append((s.link, point, 20.0 * force / np.linalg.norm(force)))
    return out


def _check_limits(scene, model, path) -> None:
    r = scene.robot
    lo, hi = model.joint_limits(unlimited=np.inf)
    assert np.all(path.q >= lo - 1e-12) and np.all(path.q <= hi + 1e-12)
    v = np.diff(path.q, axis=0) / np.diff(path.t)[:, None]
    assert np.all(np.abs(v) <= r.max_speed * 1.02 + 1e-9), np.abs(v).max(axis=0) / r.max_speed
    # the acceleration between setpoints (the last interval is shorter: compare where both are a period)
    a = np.diff(v[:-1], axis=0) / PERIOD_S
    assert np.all(np.abs(a) <= r.max_acceleration * 1.05 + 1e-6), np.abs(a).max(axis=0) / r.max_acceleration


def test_the_point_goes_back_along_the_force_by_the_distance(arm):
    scene, model = arm
    q0 = np.array(scene.robot.home)
    rng = np.random.default_rng(3)
    settings = RetreatSettings(distance_m=0.03)
    clipped = exact = 0
    for link, point, force in _contacts(model, q0, rng, 12):
        path = plan_retreat(model, q0, link=link, point=point, direction=force, settings=settings, period_s=PERIOD_S)
        u = force / np.linalg.norm(force)
        assert np.allclose(path.direction, u)
        assert np.allclose(path.q[0], q0) and path.t[0] == 0.0 and path.t[-1] == pytest.approx(path.duration_s)
        end = point_at(model, q0, path.q[-1], link=link, point=point)
        along = float((end - point) @ u)
        assert along == pytest.approx(path.moved_m, abs=1e-9)
        if path.clipped:  # a joint range stopped it (checked below): short of the distance, and said so
            assert along < 0.03
        elif np.linalg.svd(model.jacobian(q0, link, point), compute_uv=False)[-1] > 0.05:
            assert along == pytest.approx(0.03, abs=5e-4), (link, point, force)  # the joints can follow a line
            exact += 1
        else:  # near a singularity (two joints, or a point near the pan axis): the damped fit falls a little short
            assert 0.85 * 0.03 <= along <= 0.03 + 5e-4, (link, point, force)
        # on (near) the straight line all the way: sideways drift small against the distance
        pts = np.array([point_at(model, q0, q, link=link, point=point) for q in path.q[::5]])
        side = (pts - point) - np.outer((pts - point) @ u, u)
        assert np.linalg.norm(side, axis=1).max() < 0.012
        _check_limits(scene, model, path)
        clipped += path.clipped
    assert clipped <= 3 and exact >= 4, (clipped, exact)  # most contacts are free to retreat, well away


def test_a_far_retreat_is_slower_and_within_the_limits(arm):
    scene, model = arm
    q0 = np.array(scene.robot.home)
    link, point, force = _contacts(model, q0, np.random.default_rng(5), 1)[0]
    short = plan_retreat(model, q0, link=link, point=point, direction=force, settings=RetreatSettings(distance_m=0.02),
                         period_s=PERIOD_S)
    far = plan_retreat(model, q0, link=link, point=point, direction=force,
                       settings=RetreatSettings(distance_m=0.1, time_limit_s=10.0), period_s=PERIOD_S)
    assert far.duration_s > short.duration_s
    _check_limits(scene, model, far)
    assert short.within(0.5) and not far.within(short.duration_s)


def test_joint_ranges_hold_where_the_line_would_leave_them():
    """dxl-arm's joint 2 at its upper limit: a retreat that needs it further is clipped there, says so,
    and moves the point less than asked."""
    scene = load_scene("dxl-arm")
    model = ArmModel(scene)
    lo, hi = model.joint_limits(unlimited=np.inf)
    q0 = np.array(scene.robot.home)
    q0[1] = hi[1] - 1e-4
    b_T_l = model.kinematics(q0)["link5"]
    point = b_T_l[:3, 3]
    jac = model.jacobian(q0, "link5", point)
    force = jac[:, 1] / np.linalg.norm(jac[:, 1])  # the way joint 2 moves the point: it would have to go on
    path = plan_retreat(model, q0, link="link5", point=point, direction=force,
                        settings=RetreatSettings(distance_m=0.08), period_s=PERIOD_S)
    assert np.all(path.q <= hi + 1e-12) and np.all(path.q >= lo - 1e-12)
    assert path.clipped


def test_the_point_goes_back_from_where_it_was_touched():
    """The arm went on 1 cm into the contact before the retreat began: the point still ends the distance
    back from where it was touched, so it travels 4 cm."""
    scene = load_scene("ur5e")
    model = ArmModel(scene)
    q_touch = np.array(scene.robot.home)
    point = model.kinematics(q_touch)["wrist_3"][:3, 3].copy()
    force = np.array([0.0, 0.0, 30.0])  # pushed up: the point goes up
    jac = model.jacobian(q_touch, "wrist_3", point)
    q_now = q_touch + np.linalg.pinv(jac) @ np.array([0.0, 0.0, -0.01])  # 1 cm further down
    path = plan_retreat(model, q_now, link="wrist_3", point=point, direction=force, settings=RetreatSettings(),
                        period_s=PERIOD_S, q_touch=q_touch)
    end = point_at(model, q_touch, path.q[-1], link="wrist_3", point=point)
    assert (end - point)[2] == pytest.approx(0.03, abs=5e-4)
    now = point_at(model, q_touch, q_now, link="wrist_3", point=point)
    assert (end - now)[2] == pytest.approx(0.04, abs=1e-3)


def test_an_unreachable_line_is_reported():
    """ur5e's shoulder, which only the pan joint moves, touched 5 mm from the pan axis: the point can only
    circle it; the path goes as far as the joints allow and says how far that is."""
    scene = load_scene("ur5e")
    model = ArmModel(scene)
    q0 = np.array(scene.robot.home)
    b_T_l = model.kinematics(q0)["shoulder"]
    point = b_T_l[:3, 3] + b_T_l[:3, :3] @ np.array([0.005, 0.0, 0.0])
    force = model.jacobian(q0, "shoulder", point)[:, 0]
    path = plan_retreat(model, q0, link="shoulder", point=point, direction=force, settings=RetreatSettings(),
                        period_s=PERIOD_S)
    end = point_at(model, q0, path.q[-1], link="shoulder", point=point)
    assert path.moved_m == pytest.approx(float((end - point) @ path.direction), abs=1e-9)
    assert 0.0 < path.moved_m < 0.02
    _check_limits(scene, model, path)


def test_a_retreat_that_cannot_be_planned_says_why():
    leng = load_scene("leng2016")
    model = ArmModel(leng)
    q0 = np.array(leng.robot.home)
    link = model.surfaces[0].link
    with pytest.raises(RetreatError, match="max_speed"):
        plan_retreat(model, q0, link=link, point=np.zeros(3), direction=[1.0, 0, 0], settings=RetreatSettings(),
                     period_s=PERIOD_S)
    ur = load_scene("ur5e")
    model = ArmModel(ur)
    with pytest.raises(RetreatError, match="no joint moves"):  # the base link: nothing moves it
        plan_retreat(model, np.array(ur.robot.home), link="base", point=np.zeros(3), direction=[1.0, 0, 0],
                     settings=RetreatSettings(), period_s=PERIOD_S)
    for bad in ([0.0, 0.0, 0.0], [np.nan, 1.0, 0.0]):
        with pytest.raises(RetreatError, match="none to retreat along"):
            plan_retreat(model, np.array(ur.robot.home), link="wrist_3", point=np.zeros(3), direction=bad,
                         settings=RetreatSettings(), period_s=PERIOD_S)
        with pytest.raises(RetreatError, match="no direction"):  # a still arm: the force must give it
            retreat_direction(model, np.array(ur.robot.home), np.zeros(6), link="wrist_3", point=np.zeros(3),
                              force=bad, settings=RetreatSettings())
    for bad in ({"distance_m": 0.0}, {"time_limit_s": -1.0}, {"guided_above": 1.5}, {"decide_s": -0.01}):
        with pytest.raises(ValueError):
            RetreatSettings(**bad)


def test_the_direction_reverses_a_moving_arm_and_follows_the_force_on_a_still_one():
    scene = load_scene("ur5e")
    model = ArmModel(scene)
    q = np.array(scene.robot.home)
    point = model.kinematics(q)["wrist_3"][:3, 3]
    force = np.array([0.0, 0.0, 12.0])
    qd = np.array([0.5, 0.0, 0.0, 0.0, 0.0, 0.0])  # panning: the wrist moves sideways at ~0.25 m/s
    v = model.jacobian(q, "wrist_3", point) @ qd
    u, why = retreat_direction(model, q, qd, link="wrist_3", point=point, force=force, settings=RetreatSettings())
    assert why == "motion" and np.allclose(u, -v / np.linalg.norm(v))
    slow = qd * 0.05 / np.linalg.norm(v) * 0.9  # just under the threshold
    u, why = retreat_direction(model, q, slow, link="wrist_3", point=point, force=force, settings=RetreatSettings())
    assert why == "force" and np.allclose(u, [0.0, 0.0, 1.0])


def test_every_point_the_contact_may_be_at_goes_back(arm):
    """The onset's estimate is centimetres off: the region (the event's ellipsoid on the arm's surface, within
    its reach) goes back the distance, every sample of it and so a true point elsewhere in it (one not among
    the samples) within the samples' spacing; the estimate goes back further, by less than ``max_scale``. On
    dxl-arm the region takes in both fingers and the hand, on ur5e the wrist's three links."""
    scene, model = arm
    q0 = np.array(scene.robot.home)
    settings = RetreatSettings(distance_m=0.03)
    samples = SurfaceSamples(model)
    link = "wrist_3" if scene.name == "ur5e" else "gripper_left_link"
    truths = sample_surface_points(model, q0, 400, np.random.default_rng(1))
    rng = np.random.default_rng(2)
    for k in range(4):
        point = model.kinematics(q0)[link][:3, 3] + rng.normal(0.0, 0.01, 3)
        force = model.jacobian(q0, link, point) @ rng.normal(0.0, 1.0, model.n_joints)
        std = np.full(3, 0.03)
        region = samples.region(q0, link=link, point=point, point_std=std, floor_m=settings.region_floor_m,
                                reach_m=settings.region_reach_m)
        path = plan_retreat(model, q0, link=link, point=point, direction=force, settings=settings,
                            period_s=PERIOD_S, region=region)
        u = path.direction
        assert path.points == len(region) > 20 and not path.time_cut
        assert path.least_m >= 0.03 - 1e-4, (k, path.least_m)
        assert 0.03 - 1e-4 <= path.moved_m <= settings.max_scale * 0.03, (k, path.moved_m)
        inside = [t for t in truths if t.link in samples.points
                  and np.sum(((t.point - point) / std) ** 2) <= CHI2_3DOF_95
                  and np.linalg.norm(t.point - point) <= settings.region_reach_m]
        for t in inside:
            moved = (point_at(model, q0, path.q[-1], link=t.link, point=t.point) - t.point) @ u
            assert moved >= 0.03 - 1e-3, (k, t.link, moved)
        _check_limits(scene, model, path)


def test_a_path_over_the_time_limit_is_cut_to_it(arm):
    """10 cm in 0.1 s is beyond the joints' limits: the path ends at the limit, within the joints' speed and
    acceleration, the point short of the distance, and it says so."""
    scene, model = arm
    q0 = np.array(scene.robot.home)
    link, point, force = _contacts(model, q0, np.random.default_rng(5), 1)[0]
    settings = RetreatSettings(distance_m=0.1, time_limit_s=0.1)
    path = plan_retreat(model, q0, link=link, point=point, direction=force, settings=settings, period_s=PERIOD_S)
    assert path.time_cut and path.needed_s > 0.1 and path.duration_s == pytest.approx(0.1)
    assert path.within(0.1) and 0.0 < path.moved_m < 0.1
    _check_limits(scene, model, path)
    free = plan_retreat(model, q0, link=link, point=point, direction=force,
                        settings=RetreatSettings(distance_m=0.1, time_limit_s=10.0), period_s=PERIOD_S)
    assert not free.time_cut and free.needed_s == pytest.approx(path.needed_s)


def test_the_line_of_actions_other_crossing_is_in_the_region():
    """dxl-arm: the onset's estimate on the right finger with a 1 cm point_std, the contact on the left one on
    the same line of action (the localization picked the wrong crossing): the region takes in the left finger
    through its tube around the line (not through the ellipsoid), and that point goes back the distance."""
    scene = load_scene("dxl-arm")
    model = ArmModel(scene)
    q0 = np.array(scene.robot.home)
    links = model.kinematics(q0)
    right, left = (links[f"gripper_{side}_link"][:3, 3] for side in ("right", "left"))
    force = 5.0 * (left - right) / np.linalg.norm(left - right)
    settings = RetreatSettings()
    samples = SurfaceSamples(model)
    kw = {"point": right, "point_std": np.full(3, 0.01), "floor_m": settings.region_floor_m,
          "reach_m": settings.region_reach_m, "force": force}
    assert "gripper_left_link" not in samples.region(q0, link="gripper_right_link", **kw).links
    region = samples.region(q0, link="gripper_right_link", tube_m=settings.region_tube_m, **kw)
    assert "gripper_left_link" in region.links
    direction = np.cross(force, [0.0, 0.0, 1.0])  # sideways to the line, as a sweep's motion would be
    path = plan_retreat(model, q0, link="gripper_right_link", point=right, direction=direction, settings=settings,
                        period_s=PERIOD_S, region=region)
    moved = (point_at(model, q0, path.q[-1], link="gripper_left_link", point=left) - left) @ path.direction
    assert moved >= 0.03 - 1e-3 and path.least_m >= 0.03 - 1e-4


def test_an_arm_that_ran_into_a_contact_retraces_its_way_wherever_the_contact_is(arm):
    """A moving arm whose estimate is on the wrong link (an onset's estimate can be 25-55 cm off on ur5e): the
    joints go back along their velocity's reverse, so a true point on another link goes back the way it came
    too (never on into what it ran into), while the estimate goes back the distance along its own way."""
    scene, model = arm
    q0 = np.array(scene.robot.home)
    rng = np.random.default_rng(7)
    truths = sample_surface_points(model, q0, 200, rng)
    settings = RetreatSettings(distance_m=0.03)
    links = [s.link for s in model.surfaces if model.moving_joints(s.link).sum() >= 2]
    planned = 0
    for k in range(12):
        qd = rng.normal(0.0, 0.5, model.n_joints)
        link = links[k % len(links)]
        point = model.kinematics(q0)[link][:3, 3]
        v = model.jacobian(q0, link, point) @ qd
        if np.linalg.norm(v) <= settings.moving_above_m_s:  # the link's origin barely moved: a still point
            continue
        direction, why = retreat_direction(model, q0, qd, link=link, point=point, force=-v, settings=settings)
        assert why == "motion"
        planned += 1
        path = plan_retreat(model, q0, link=link, point=point, direction=direction, settings=settings,
                            period_s=PERIOD_S, qd_touch=qd)
        assert np.allclose(path.direction, -v / np.linalg.norm(v)) and path.moved_m >= 0.03 - 1e-4, k
        dq = path.q[-1] - q0
        assert np.allclose(dq / np.linalg.norm(dq), -qd / np.linalg.norm(qd))  # straight back along -qd
        for t in truths:
            came = model.jacobian(q0, t.link, t.point) @ qd  # its velocity at the touch
            if np.linalg.norm(came) < 0.05:
                continue
            moved = point_at(model, q0, path.q[-1], link=t.link, point=t.point) - t.point
            assert moved @ came < 0.0, (k, t.link)  # back the way it came, on any link
        _check_limits(scene, model, path)
    assert planned >= 6
