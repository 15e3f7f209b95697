"""The true shell in the world: a user's URDF whose touchable links are meshes (the pipeline fits
primitives, the world presses the meshes) and the UR5e vendor meshes under a typical reality."""
from __future__ import annotations

import dataclasses
import zipfile

import mujoco
import numpy as np
import pytest

from ftc_hw.app.setup.vendor_meshes import VendorFetchError, _unpack
from ftc_hw.model import ArmModel
from ftc_hw.model.mesh_fit import SURFACE_GROUP
from ftc_hw.scene import SceneError, load_scene
from ftc_hw.scene.loader import builtin_dir
from ftc_hw.scene.vendor import shell_fetched
from ftc_hw.sim_devices.world import World, build_scenario, with_reality
from ftc_hw.sim_devices.world.true_shell import shell_meshes
from tests.urdf_arm import write_ur5e_urdf

pytestmark = pytest.mark.compute  # computes only (nothing timed): runs with the others on every core

UR5E = load_scene("ur5e")


def _moved(setup, world) -> np.ndarray:
    """How far (m) the world moved each probe's point from the model's surface onto the true shell."""
    return np.array([np.linalg.norm(a.point_link - b.point_link)
                     for a, b in zip(setup.probes, world.setup.probes, strict=True)])


@pytest.fixture(scope="module")
def user_scene(tmp_path_factory):
    return load_scene(str(write_ur5e_urdf(tmp_path_factory.mktemp("urdf"))))


def test_a_urdf_with_mesh_collisions_is_the_same_arm_on_fitted_primitives(user_scene):
    user, ur5e = ArmModel(user_scene), ArmModel(UR5E)
    assert {s.link for s in user.surfaces} == {t.link for t in user_scene.touchable}
    assert len(user.mesh_fits) == len(ur5e.surfaces) == len(user.surfaces)
    assert all(f.rms_m < 1.5e-3 for f in user.mesh_fits)  # 16-sided prisms and domes: ~1 mm off round
    kinds = {f.geom: f.kind for f in user.mesh_fits}
    assert kinds["upper_arm_2"] == "capsule" and kinds["base_0"] == "cylinder"  # the tube; a flat disc
    rng = np.random.default_rng(0)
    for _ in range(3):
        q, qd, qdd = rng.uniform(-2, 2, (3, 6))
        np.testing.assert_allclose(user.predicted_wrench(q, qd, qdd), ur5e.predicted_wrench(q, qd, qdd), atol=1e-7)
    fit = max(f.rms_m for f in user.mesh_fits if f.link == "forearm")
    assert user.surface_tolerance("forearm") == pytest.approx(np.hypot(UR5E.robot.surface_tolerance, fit))
    assert user.surface_tolerance("forearm") > ur5e.surface_tolerance("forearm")


def test_the_world_presses_the_users_meshes_not_the_fit(user_scene):
    arm = ArmModel(user_scene)
    setup = build_scenario("static-pokes", user_scene, arm, seed=0, duration=6.0)
    world = World(user_scene, setup, noise=False)
    m = world.model
    meshes = [g for g in range(m.ngeom) if m.geom_group[g] == SURFACE_GROUP and m.geom_type[g] == 7]
    assert len(meshes) == len(arm.surfaces)  # the world keeps the meshes: they are its shell
    assert world.probes_off_mesh == 0 and all(p.on_true_shell for p in world.setup.probes)
    moved = _moved(setup, world)
    assert 0.0 < np.median(moved) < 2e-3 and moved.max() < 6e-3  # a polygon's flats are inside the round


def test_a_typical_ur5e_world_is_touched_on_the_vendor_meshes():
    assert shell_fetched("robosuite-ur5e"), "scripts/bootstrap.sh fetches them: ftc scenes --fetch-meshes"
    scene = with_reality(UR5E, "typical", seed=0)
    assert scene.world.vendor_shell == "robosuite-ur5e"
    arm = ArmModel(UR5E)
    setup = build_scenario("static-pokes", scene, arm, seed=1, duration=15.0)
    world = World(scene, setup, noise=False)
    m = world.model
    surface = [g for g in range(m.ngeom) if m.geom_group[g] == SURFACE_GROUP]
    assert surface and all(m.geom_type[g] == 7 for g in surface)  # primitives are out of the surface
    assert all(p.on_true_shell for p in world.setup.probes)
    moved = _moved(setup, world)
    # UR's meshes lie within a few millimetres of the primitives, and up to ~16 mm where the primitives
    # round a flange or a recess the mesh has
    assert 0.3e-3 < np.median(moved) < 5e-3 and moved.max() < 0.03
    probe = world.setup.probes[0]
    world.start_script()
    truth = [c for state, _ in world.run(probe.t_start + probe.ramp_s + 0.01) for c in state.contacts][-1]
    bid = m.body(probe.link).id
    np.testing.assert_allclose(world.data.xmat[bid].reshape(3, 3).T @ (truth.point - world.data.xpos[bid]),
                               probe.point_link, atol=1e-9)


def test_a_wheel_without_the_named_meshes_is_a_clear_error(tmp_path):
    wheel = tmp_path / "pkg-1.0-py3-none-any.whl"
    with zipfile.ZipFile(wheel, "w") as z:
        z.writestr("pkg/robot/robot.xml", '<mujoco><asset><mesh name="a" file="meshes/a.stl"/></asset></mujoco>')
    with pytest.raises(VendorFetchError, match="no pkg/robot/meshes/a.stl"):
        _unpack(wheel, "pkg/robot", "robot.xml", "LICENSE", tmp_path / "out")
    with pytest.raises(VendorFetchError, match="no pkg/other/robot.xml"):
        _unpack(wheel, "pkg/other", "robot.xml", "LICENSE", tmp_path / "out2")


def test_the_sweeps_obstacle_meets_the_vendor_meshes_and_the_truth_is_on_them():
    """MuJoCo collides the meshes (their parts' hulls), not the primitives they replaced; the truth point
    is where the contact's line of action meets the mesh's own triangles."""
    scene = with_reality(UR5E, "typical", seed=0)
    setup = build_scenario("sweep-with-collision", scene, ArmModel(UR5E), seed=0, duration=3.0)
    world = World(scene, setup, noise=False)
    m, d = world.model, world.data
    touched, on_mesh = set(), []
    for state, _ in world.run(3.0):
        for i in range(d.ncon):
            touched |= {m.geom(int(g)).name for g in (d.contact[i].geom1, d.contact[i].geom2)}
        for c in state.contacts:
            if not np.linalg.norm(c.force) > 0.0:
                continue
            u = c.force / np.linalg.norm(c.force)
            hits = [mujoco.mj_rayMesh(m, d, g, c.point - 1e-3 * u, u) for g in shell_meshes(m, m.body(c.link).id)]
            on_mesh.append(min((h for h in hits if h >= 0.0), default=np.nan))
    assert on_mesh and touched - {"ftc_obstacle0_geom"} and all(n.startswith("vendor_") for n in touched - {
        "ftc_obstacle0_geom"})
    assert np.max(np.abs(np.array(on_mesh) - 1e-3)) < 1e-6  # 1 mm back along the line: the mesh


def test_a_drawn_shift_moves_the_vendor_shell_and_a_bad_one_is_named(tmp_path):
    scene = with_reality(UR5E, "typical", seed=0)
    shifts = scene.world.vendor_shell_shift
    assert set(shifts) == {"base", "shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3"}
    assert all(np.all(np.abs(v) <= 1e-3) for v in shifts.values()) and any(np.any(v) for v in shifts.values())
    arm = ArmModel(UR5E)
    setup = build_scenario("static-pokes", scene, arm, seed=1, duration=3.0)
    unshifted = World(dataclasses.replace(scene, world=dataclasses.replace(scene.world, vendor_shell_shift={})),
                      setup, noise=False)
    shifted = World(scene, setup, noise=False)
    p, q = unshifted.setup.probes[0], shifted.setup.probes[0]
    # the probe meets the shifted shell along its ray: moved by the shift's part along the normal (or more)
    n = p.normal_link / np.linalg.norm(p.normal_link)
    assert np.linalg.norm(q.point_link - p.point_link) > 0.2 * abs(shifts[p.link] @ n)
    assert np.linalg.norm(q.point_link - p.point_link) > 0.0
    assert World(scene, build_scenario("sweep", scene, arm, seed=1, duration=1.0)).model.nmesh == 0  # untouched
    toml = (builtin_dir() / "ur5e.toml").read_text().replace("[gravity]", "[world.vendor_shell_shift_m]\nelbow = "
                                                              "[0.0, 0.0, 0.001]\n\n[gravity]")
    (tmp_path / "ur5e.xml").write_text((builtin_dir() / "ur5e.xml").read_text())
    (tmp_path / "ur5e.toml").write_text(toml)
    with pytest.raises(SceneError, match="vendor_shell_shift_m.elbow"):
        World(load_scene(str(tmp_path / "ur5e.toml")), setup, noise=False)
