"""The pipeline answers on the scene's meshes where it has them: an event's point is where its line of
action enters the touched link's meshes (UR's, for ur5e), not the primitives the solver fits."""
from __future__ import annotations

import numpy as np
import pytest

from ftc_hw.bus import ContactEvent
from ftc_hw.model import ArmModel, Contact
from ftc_hw.model.mesh_surface import pipeline_mesh_shell
from ftc_hw.pipeline import ContactPipeline
from ftc_hw.scene import load_scene
from ftc_hw.scene.vendor import VENDOR_SHELLS, shell_fetched
from tests.conftest import settings

UR5E = load_scene("ur5e")
HOME = np.array(UR5E.robot.home, dtype=float)
MS = 1_000_000


def _onset(pipe: ContactPipeline, wrench: np.ndarray):
    for k in range(20):
        pipe.process(k * MS, np.zeros(6), HOME)
    events = [e for k in range(20, 30) for e in pipe.process(k * MS, wrench, HOME).events]
    return next(e for e in events if e.kind == "onset")


@pytest.mark.parametrize("link", ["upper_arm", "wrist_2"])
def test_an_event_on_a_meshed_link_lies_on_its_meshes(link):
    assert shell_fetched("robosuite-ur5e"), "scripts/bootstrap.sh fetches them: ftc scenes --fetch-meshes"
    model = ArmModel(UR5E)
    shell = pipeline_mesh_shell(UR5E)
    links = model.kinematics(HOME)
    surf = next(s for s in model.surfaces if s.link == link)
    centre = (links[link] @ surf.link_T_geom)[:3, 3]
    inward = np.array([0.0, 1.0, 0.0])
    on_mesh = shell.entry(link, HOME, centre, inward)  # where a push along +y meets the link's meshes
    assert on_mesh is not None
    wrench = model.predicted_wrench(HOME, level="bias", contacts=[Contact(link, on_mesh, 40.0 * inward)])
    kwargs = dict(level="bias", bias=np.zeros(6), use_currents=False)
    meshes = _onset(ContactPipeline(UR5E, settings(**kwargs)), wrench)
    primitives = _onset(ContactPipeline(UR5E, settings(surface="primitives", **kwargs)), wrench)
    assert meshes.link == primitives.link == link
    assert np.linalg.norm(meshes.point - on_mesh) < 1e-6
    assert np.linalg.norm(primitives.point - on_mesh) > 2e-4  # the primitives round UR's shapes off
    # the real shell's distance from UR's meshes (their tolerance) in place of its distance from the primitives
    swap = VENDOR_SHELLS["robosuite-ur5e"].tolerance_m ** 2 - UR5E.robot.surface_tolerance ** 2
    np.testing.assert_allclose(meshes.point_std ** 2, primitives.point_std ** 2 + swap, rtol=1e-9)


def test_the_surface_answered_on_is_said_and_a_bad_one_refused():
    assert ContactPipeline(UR5E, settings(level="bias")).surface_source == "meshes"
    assert ContactPipeline(UR5E, settings(level="bias", surface="primitives")).surface_source == "primitives"
    assert ContactPipeline(load_scene("dxl-arm"), settings(level="bias")).surface_source == "primitives"  # no meshes
    with pytest.raises(ValueError, match="surface: expected 'meshes' or 'primitives', got 'hull'"):
        ContactPipeline(UR5E, settings(level="bias", surface="hull"))


def test_the_line_followed_is_the_wrenchs_not_the_solvers_point():
    """Where the real shell stands out of the primitives, the true line misses them and the solver's point
    is off it: the point is moved onto the line the external wrench acts along, then into the meshes."""
    model = ArmModel(UR5E)
    pipe = ContactPipeline(UR5E, settings(level="bias", bias=np.zeros(6), use_currents=False))
    link = "upper_arm"
    surf = next(s for s in model.surfaces if s.link == link)
    centre = (model.kinematics(HOME)[link] @ surf.link_T_geom)[:3, 3]
    push = np.array([0.0, 40.0, 0.0])
    on_mesh = pipe.events.mesh_shell.entry(link, HOME, centre, push)
    b_T_s = model.base_T_sensor(HOME)
    f_s, c_s = b_T_s[:3, :3].T @ push, b_T_s[:3, :3].T @ (on_mesh - b_T_s[:3, 3])
    wrench = np.r_[f_s, np.cross(c_s, f_s)]  # the push as the sensor sees it: m = c x f
    off = on_mesh + np.array([0.004, 0.0, 0.0])  # a point 4 mm off the line, as a primitive's might be
    ev = ContactEvent.make(0, "update", link, off, push, (0.002, 0.002, 0.002))
    assert np.linalg.norm(pipe.events.on_meshes(ev, HOME, wrench=wrench).point - on_mesh) < 1e-6
    assert np.linalg.norm(pipe.events.on_meshes(ev, HOME).point - on_mesh) > 3e-3  # its own line: 4 mm off


def test_the_recent_wrench_is_the_mean_of_the_last_update_period():
    pipe = ContactPipeline(UR5E, settings(level="bias"))
    window = round(pipe.events.update_period_ns * 1e-9 * UR5E.sensor.rate_hz)
    xs = np.random.default_rng(0).normal(size=(3 * window + 7, 6))
    for i, x in enumerate(xs):
        pipe.events._add_recent(x)
        want = xs[max(0, i + 1 - window):i + 1].mean(axis=0)
        np.testing.assert_allclose(pipe.events.recent_external(), want, atol=1e-12)
