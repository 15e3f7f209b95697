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
    """MuJoCo force and torque sensors at the scene's sensor site.

    They report the wrench the parent body exerts on the site's body, in the site frame, about the
    site: the ``base_on_arm`` convention when the site's body is the arm's root.
    """
    site = scene.sensor.site
    if spec.site(site) is None:
        raise SceneError(scene.path, "sensor.site", f"no site {site!r} in {scene.robot.model_path.name}")
    for kind, name in ((mujoco.mjtSensor.mjSENS_FORCE, FORCE_SENSOR), (mujoco.mjtSensor.mjSENS_TORQUE, TORQUE_SENSOR)):
        spec.add_sensor(type=kind, objtype=mujoco.mjtObj.mjOBJ_SITE, objname=site, name=name)


def attach_payload(spec: mujoco.MjSpec, scene: Scene, payload: Payload) -> None:
    """A point-like payload body fixed at the scene's flange site."""
    flange = scene.robot.flange
    if flange is None:
        raise SceneError(scene.path, "robot.flange", "a payload needs the flange site named in the scene")
    site = spec.site(flange)
    if site is None:
        raise SceneError(scene.path, "robot.flange", f"no site {flange!r} in {scene.robot.model_path.name}")
    parent = site.parent
    body = parent.add_body(name="ftc_payload", pos=site.pos, quat=site.quat)
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
