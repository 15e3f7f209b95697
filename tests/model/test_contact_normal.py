"""A contact's normal: the surface's at the point (the primitives', or the meshes' where the pipeline answers on
them), pulled into the force's friction cone where it leans out of it."""
from __future__ import annotations

import math

import numpy as np
import pytest

from ftc_hw.model import ArmModel
from ftc_hw.model.contact_normal import contact_normal, primitive_normal, within_cone
from ftc_hw.model.mesh_surface import pipeline_mesh_shell
from ftc_hw.model.sampling import sample_surface_points
from ftc_hw.scene import load_scene
from ftc_hw.scene.vendor import shell_fetched
from ftc_hw.sim_devices.world.scenarios import visible_filter

UR5E = load_scene("ur5e")
HOME = np.array(UR5E.robot.home, dtype=float)


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(float(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1.0, 1.0))))


def test_the_primitives_normal_is_the_sampled_points_own():
    """At points of the arm's outer surface (two primitives meeting face to face share hidden points)."""
    model = ArmModel(UR5E)
    surfaces = model.posed_surfaces(HOME)
    for sp in sample_surface_points(model, HOME, 40, np.random.default_rng(1), hidden=visible_filter(model, HOME)):
        np.testing.assert_allclose(primitive_normal(surfaces, sp.link, sp.point), sp.normal, atol=1e-9)
    assert primitive_normal(surfaces, "no_such_link", np.zeros(3)) is None


def test_a_normal_out_of_the_friction_cone_is_pulled_onto_its_boundary():
    axis = np.array([0.0, 0.0, 1.0])
    inside = np.array([math.sin(0.5), 0.0, math.cos(0.5)])
    assert within_cone(inside, axis, math.pi / 4) is inside
    out = within_cone(np.array([1.0, 0.0, 0.0]), axis, math.pi / 4)
    np.testing.assert_allclose(out, [math.sqrt(0.5), 0.0, math.sqrt(0.5)], atol=1e-12)  # in the plane of the two
    np.testing.assert_allclose(within_cone(-axis, axis, math.pi / 4), axis)


@pytest.mark.parametrize("link", ["upper_arm", "forearm", "wrist_2"])
def test_the_meshes_normal_faces_the_push_and_near_the_primitives(link):
    assert shell_fetched("robosuite-ur5e"), "scripts/bootstrap.sh fetches them: ftc scenes --fetch-meshes"
    model, shell = ArmModel(UR5E), pipeline_mesh_shell(UR5E)
    surf = next(s for s in model.surfaces if s.link == link)
    centre = (model.kinematics(HOME)[link] @ surf.link_T_geom)[:3, 3]
    push = np.array([0.0, 1.0, 0.0])  # N, applied to the arm
    point = shell.entry(link, HOME, centre, push)
    normal = shell.normal(link, HOME, point, push)
    assert normal is not None and np.linalg.norm(normal) == pytest.approx(1.0)
    assert normal @ push < 0  # outward: against the push
    assert _angle(normal, primitive_normal(model.posed_surfaces(HOME), link, point)) < 30  # UR's round shapes
    assert shell.normal("base_link_inertia_no_such", HOME, point, push) is None
    # the pipeline's one: the meshes', or the cone's boundary where the push leans more (mu 1: 45 degrees)
    n = contact_normal(arm=model, shell=shell, link=link, q=HOME, point=point, force=push, mu=1.0)
    if _angle(normal, -push) <= 45:
        np.testing.assert_allclose(n, normal, atol=1e-12)
    else:
        assert _angle(n, -push) == pytest.approx(45.0, abs=1e-6)


def test_without_meshes_the_primitives_normal_within_the_cone():
    model = ArmModel(UR5E)
    sp = sample_surface_points(model, HOME, 1, np.random.default_rng(2), hidden=visible_filter(model, HOME))[0]
    tangent = np.cross(sp.normal, [1.0, 0.0, 0.0] if abs(sp.normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    tangent /= np.linalg.norm(tangent)
    straight = -sp.normal * 30.0  # N, pushing straight in
    n = contact_normal(arm=model, shell=None, link=sp.link, q=HOME, point=sp.point, force=straight, mu=1.0)
    np.testing.assert_allclose(n, sp.normal, atol=1e-9)
    leaning = 30.0 * (-math.cos(math.radians(60)) * sp.normal + math.sin(math.radians(60)) * tangent)
    n = contact_normal(arm=model, shell=None, link=sp.link, q=HOME, point=sp.point, force=leaning, mu=1.0)
    assert _angle(n, -leaning) == pytest.approx(45.0, abs=1e-6)  # friction allows no more than atan(mu)
    assert _angle(n, sp.normal) == pytest.approx(15.0, abs=1e-6)
