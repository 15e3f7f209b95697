"""The true arm of a scene's world: the robot file (or ``[world] model``) with the scene's
``[world]`` differences applied. Only the simulated world builds it; the pipeline never sees it.

``true_arm_spec`` loads and checks the file; the caller adds what its world needs (sensors,
payload, obstacles), then ``compile_true_arm`` inflates the shells, compiles, and applies the
inertial and sensor-mount differences to the compiled model.
"""
from __future__ import annotations

import mujoco
import numpy as np

from ..scene import Scene, SceneError
from ..scene.vendor import shell_fetched
from ..scene.world_spec import WorldSpec
from .build import arm_bodies, ft_site_id, load_spec, parse_spec
from .mesh_fit import SURFACE_GROUP, prepare_user_model
from .vendor_shell import attach_vendor_shell

_INFLATED_AXES = {  # per geom type: which size entries grow by the shell offset
    mujoco.mjtGeom.mjGEOM_SPHERE: (0,), mujoco.mjtGeom.mjGEOM_CAPSULE: (0,),
    mujoco.mjtGeom.mjGEOM_CYLINDER: (0, 1), mujoco.mjtGeom.mjGEOM_BOX: (0, 1, 2),
    mujoco.mjtGeom.mjGEOM_ELLIPSOID: (0, 1, 2),
}


def true_arm_spec(scene: Scene, shell: str = "collide") -> mujoco.MjSpec:
    """The true arm's file, loaded and checked against the scene's model: same joints, bodies for every
    touchable link and every ``[world.inertials]`` entry, the sensor site. ``shell``: what the vendor
    meshes (:func:`world_vendor_shell`) are there for: ``collide`` (obstacles meet them: MuJoCo hulls
    them, seconds on a fresh process), ``rays`` (probes press them) or ``none`` (nothing touches the
    arm: the meshes, massless, change nothing)."""
    world = scene.world
    if world.model_path is None:
        spec = load_spec(scene, fit_meshes=False)  # a mesh is the true shell, not its fit
    else:
        spec = parse_spec(scene, world.model_path, "world.model")
        prepare_user_model(spec, scene, urdf=world.model_path.suffix.lower() == ".urdf")
        _check_same_arm(scene, spec)
    vendor = world_vendor_shell(scene)
    if vendor is not None and shell != "none":
        attach_vendor_shell(spec, scene, vendor, collide=shell == "collide", shifts=world.vendor_shell_shift)
    elif vendor is None and world.vendor_shell_shift:
        raise SceneError(scene.path, "world.vendor_shell_shift_m", "a shift of the vendor shell, but no vendor_shell")
    for body in world.inertials:
        if spec.body(body) is None:
            raise SceneError(scene.path, f"world.inertials.{body}", f"no body {body!r} in the world's arm")
    return spec


def world_vendor_shell(scene: Scene) -> str | None:
    """The vendor meshes that are the world's shell: its ``[world] vendor_shell``; else, unless the world
    offsets the primitives (``shell_offset_m``: that shell is meant), the model's own (``[robot]
    vendor_shell``, where fetched: the surface the pipeline answers on, so the ideal world is the
    pipeline's model, meshes and all)."""
    w = scene.world
    if w.vendor_shell is not None:
        return w.vendor_shell
    name = scene.robot.vendor_shell
    offset = w.shell_offset or any(w.shell_offsets.values())
    return name if name is not None and not offset and shell_fetched(name) else None


def _check_same_arm(scene: Scene, spec: mujoco.MjSpec) -> None:
    name = scene.world.model_path.name if scene.world.model_path else "?"
    needed = list(scene.robot.joints) + [d for c in scene.robot.couplings for d in c.drives]
    coupled = {c.joint for c in scene.robot.couplings}
    for joint in needed:
        if joint not in coupled and spec.joint(joint) is None:
            raise SceneError(scene.path, "world.model", f"{name} has no joint {joint!r} (the scene's model has it)")
    for t in scene.touchable:
        if spec.body(t.link) is None:
            raise SceneError(scene.path, "world.model", f"{name} has no body {t.link!r} (a touchable link)")
    if scene.sensor is not None and spec.site(scene.sensor.site) is None:
        raise SceneError(scene.path, "world.model", f"{name} has no site {scene.sensor.site!r} (the sensor)")
    for body in spec.bodies:
        if body.explicitinertial and (body.mass < 0 or np.any(np.asarray(body.inertia) < 0)):
            raise SceneError(scene.path, "world.model", f"{name}: body {body.name!r} has a negative mass or inertia")


def compile_true_arm(scene: Scene, spec: mujoco.MjSpec) -> mujoco.MjModel:
    """Compile ``spec`` as the true arm: the shells of the arm's bodies (:func:`.build.arm_bodies`: those a
    base sensor carries) inflated (their inertials kept as the uninflated model's), then the inertial
    and sensor-mount differences applied."""
    world = scene.world
    try:
        reference = spec.compile()
        arm = {reference.body(b).name for b in arm_bodies(reference, scene)}
        _inflate_shells(spec, world, arm)
        m = spec.compile()
    except ValueError as exc:
        key = "world.model" if world.model_path else "robot.model"
        raise SceneError(scene.path, key, f"MuJoCo cannot compile the world's arm: {exc}") from exc
    for attr in ("body_mass", "body_ipos", "body_iquat", "body_inertia"):
        getattr(m, attr)[:] = getattr(reference, attr)
    for body, err in world.inertials.items():
        b = m.body(body).id
        m.body_mass[b] *= err.mass_scale
        m.body_ipos[b] += err.com_offset
        m.body_inertia[b] *= err.inertia_scale
    if np.any(m.body_mass[1:] < 0):
        raise SceneError(scene.path, "world.inertials", "a body's mass came out negative")
    _move_sensor(m, scene)
    return m


def _inflate_shells(spec: mujoco.MjSpec, world: WorldSpec, arm_bodies: set[str]) -> None:
    for geom in spec.geoms:
        axes = _INFLATED_AXES.get(geom.type)
        if axes is None or geom.group != SURFACE_GROUP or geom.parent.name not in arm_bodies:
            continue
        offset = world.shell_of(geom.name)
        if offset:
            size = np.array(geom.size, dtype=float)
            size[list(axes)] += offset
            geom.size = size


def _move_sensor(m: mujoco.MjModel, scene: Scene) -> None:
    """The sensor's true mount: moved by ``sensor_offset`` (its own frame) and turned by ``sensor_rotation``."""
    w = scene.world
    sid = ft_site_id(m, scene)
    if sid is None:
        return
    if np.any(w.sensor_offset):
        r = np.empty(9)
        mujoco.mju_quat2Mat(r, m.site_quat[sid])
        m.site_pos[sid] += r.reshape(3, 3) @ w.sensor_offset
    angle = float(np.linalg.norm(w.sensor_rotation))
    if angle > 0:
        turn, out = np.empty(4), np.empty(4)
        mujoco.mju_axisAngle2Quat(turn, w.sensor_rotation / angle, angle)
        mujoco.mju_mulQuat(out, m.site_quat[sid], turn)
        m.site_quat[sid] = out
