"""Building the MuJoCo model of a scene: the robot file plus the sensor and an optional payload."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from ..scene import Scene, SceneError
from .mesh_fit import MeshFit, fit_mesh_surfaces, prepare_user_model

FORCE_SENSOR = "ftc_force"
TORQUE_SENSOR = "ftc_torque"
# A flange-mounted sensor's tool side: a body added to the sensor site's link (at the link's frame), with
# the measuring site at the scene's site pose; what the sensor carries (the payload) hangs from it
FT_TOOL_BODY = "ftc_ft_tool"
FT_SITE = "ftc_ft_site"


@dataclass(frozen=True)
class Payload:
    """A rigid payload on the flange: mass (kg) and centre of mass (m, flange frame)."""

    mass: float
    com: tuple[float, float, float]

    def __post_init__(self) -> None:
        if not (np.isfinite(self.mass) and self.mass > 0):
            raise ValueError(f"payload mass must be a positive number of kg, got {self.mass}")
        if len(self.com) != 3 or not np.all(np.isfinite(self.com)):
            raise ValueError(f"payload centre of mass must be 3 finite numbers in m, got {self.com}")


def load_spec(scene: Scene, fit_meshes: bool = True) -> mujoco.MjSpec:
    """The scene's robot file as a MuJoCo spec: a URDF's sensor site and flange made sites, touchable
    collision geoms in the surface group, and (``fit_meshes``) touchable meshes fitted by primitives
    (:mod:`.mesh_fit`; the world keeps the meshes: they are its true shell)."""
    return load_spec_and_fits(scene, fit_meshes)[0]


def load_spec_and_fits(scene: Scene, fit_meshes: bool = True) -> tuple[mujoco.MjSpec, tuple[MeshFit, ...]]:
    path = scene.robot.model_path
    spec = parse_spec(scene, path, "robot.model")
    prepare_user_model(spec, scene, urdf=path.suffix.lower() == ".urdf")
    fits: tuple[MeshFit, ...] = ()
    if fit_meshes:
        try:
            fits = fit_mesh_surfaces(spec, scene)
        except ValueError as exc:
            raise SceneError(scene.path, "robot.model",
                             f"MuJoCo cannot fit primitives to {path.name}'s meshes: {exc}") from exc
    return spec, fits


def parse_spec(scene: Scene, path: Path, key: str) -> mujoco.MjSpec:
    try:
        # MuJoCo's parser reads both MJCF and URDF.
        spec = mujoco.MjSpec.from_file(str(path))
    except Exception as exc:  # mujoco raises ValueError with the parser's message
        raise SceneError(scene.path, key, f"MuJoCo cannot load {path.name}: {exc}") from exc
    spec.option.gravity = np.asarray(scene.gravity, dtype=float)
    return spec


def add_ft_sensors(spec: mujoco.MjSpec, scene: Scene) -> None:
    """MuJoCo force and torque sensors at the scene's F/T sensor (none when the scene has none).

    They report the wrench the parent body exerts on the site's body (and so on its subtree), in the
    site frame, about the site: the ``base_on_arm`` convention when the site's body is the arm's root.
    A ``flange`` mount measures between the flange and the tool: where its site is on a link (a body
    with a joint), the sensor gets a body of its own on that link (``FT_TOOL_BODY``, at the link's
    frame, massless) holding the measuring site (``FT_SITE``, the scene site's pose), so that it carries
    only what hangs beyond it (the payload: :func:`attach_payload`), not the link; where its site is on
    a joint-less tool body, that body's subtree is what it carries.
    """
    sensor = scene.sensor
    if sensor is None:
        return
    site = spec.site(sensor.site)
    if site is None:
        raise SceneError(scene.path, "sensor.site", f"no site {sensor.site!r} in {scene.robot.model_path.name}")
    name = sensor.site
    if sensor.mount == "flange" and _has_joint(site.parent):
        tool = site.parent.add_body(name=FT_TOOL_BODY)
        ft = tool.add_site(name=FT_SITE, pos=site.pos, quat=site.quat)
        ft.alt = site.alt  # an orientation given otherwise than as a quaternion
        name = FT_SITE
    for kind, sensor_name in ((mujoco.mjtSensor.mjSENS_FORCE, FORCE_SENSOR),
                              (mujoco.mjtSensor.mjSENS_TORQUE, TORQUE_SENSOR)):
        spec.add_sensor(type=kind, objtype=mujoco.mjtObj.mjOBJ_SITE, objname=name, name=sensor_name)


def _has_joint(body: mujoco.MjsBody) -> bool:
    return body.first_joint() is not None


def ft_site_id(m: mujoco.MjModel, scene: Scene) -> int | None:
    """The site id the F/T sensor measures at in a model built with :func:`add_ft_sensors` (None: the
    scene has no F/T sensor)."""
    if scene.sensor is None:
        return None
    try:
        return int(m.site(FT_SITE).id)
    except KeyError:
        return int(m.site(scene.sensor.site).id)


def arm_bodies(m: mujoco.MjModel, scene: Scene) -> list[int]:
    """The arm's bodies (ids, the world excluded): with a base F/T sensor those it carries (its site's
    body's subtree); without one or with a flange sensor every body of ``m`` but the world."""
    s = scene.sensor
    if s is not None and s.mount == "base":
        root = int(m.site_bodyid[m.site(s.site).id])
        return [b for b in range(1, m.nbody) if descends(m, b, root)]
    return list(range(1, m.nbody))


def attach_payload(spec: mujoco.MjSpec, scene: Scene, payload: Payload) -> None:
    """A point-like payload body fixed at the scene's flange site (beyond a flange-mounted F/T sensor:
    call :func:`add_ft_sensors` first)."""
    flange = scene.robot.flange
    if flange is None:
        raise SceneError(scene.path, "robot.flange", "a payload needs the flange site named in the scene")
    site = spec.site(flange)
    if site is None:
        raise SceneError(scene.path, "robot.flange", f"no site {flange!r} in {scene.robot.model_path.name}")
    parent = site.parent
    tool = spec.body(FT_TOOL_BODY)
    if tool is not None and tool.parent.name == parent.name:
        parent = tool  # at the link's frame: the flange site's pose holds in it
    elif tool is not None:
        raise SceneError(scene.path, "robot.flange", f"the flange site {flange!r} is not on the flange sensor's "
                         f"link {tool.parent.name!r}: a payload there would not hang from the sensor")
    body = parent.add_body(name="ftc_payload", pos=site.pos, quat=site.quat)
    body.alt = site.alt
    # A small sphere's inertia: the payload model identifies mass and centre of mass only.
    i = 0.4 * payload.mass * 0.02**2
    body.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.02, 0, 0], pos=list(payload.com),
                  mass=payload.mass, contype=0, conaffinity=0, group=2)
    body.explicitinertial = True
    body.mass = payload.mass
    body.ipos = list(payload.com)
    body.inertia = [i, i, i]


def moves(m: mujoco.MjModel, body: int) -> bool:
    """True when a joint moves ``body``: its own, or one of an ancestor's."""
    while body > 0:
        if m.body_jntnum[body] > 0:
            return True
        body = int(m.body_parentid[body])
    return False


def descends(m: mujoco.MjModel, body: int, ancestor: int) -> bool:
    """True when ``body`` is ``ancestor`` or in its subtree (the bodies whose loads it carries)."""
    while True:
        if body == ancestor:
            return True
        if body == 0:
            return False
        body = int(m.body_parentid[body])
