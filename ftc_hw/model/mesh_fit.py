"""A user's robot file whose touchable links are meshes (what a URDF's ``<collision>`` elements hold):
each mesh geom becomes the primitive that fits it best, and the fit's error is kept.

MuJoCo does the fitting (a primitive geom with a ``mesh`` attribute is fitted to the mesh: to its
inertia box, or with ``compiler fitaabb`` to its bounding box); this module only tries each primitive
kind both ways and keeps, per geom, the one whose surface lies closest to the mesh's surface. The
distance is measured on points spread over the mesh's triangles by area (the geometry engine's
closest-point projection), so a fit's ``rms_m`` is the 1-sigma distance between a contact on the real
(mesh) shell and the model's surface: the pipeline adds it to the link's surface tolerance.

URDF files carry no sites and no geom groups: the sensor site and flange may name a link (the site is
then that link's frame), and a URDF's collision geoms of the touchable links are the surfaces.
"""
from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from ..geometry.arrays import project
from ..scene import Scene
from .rates import sample_rate_hz

SURFACE_GROUP = 1  # MJCF geom group that holds the touchable surfaces (ftc_hw.model.arm re-exports it)
_KINDS = {mujoco.mjtGeom.mjGEOM_CAPSULE: "capsule", mujoco.mjtGeom.mjGEOM_CYLINDER: "cylinder",
          mujoco.mjtGeom.mjGEOM_BOX: "box", mujoco.mjtGeom.mjGEOM_ELLIPSOID: "ellipsoid",
          mujoco.mjtGeom.mjGEOM_SPHERE: "sphere"}
_SAMPLES = 4000  # points per mesh for the fit error


@dataclass(frozen=True)
class MeshFit:
    """How a touchable mesh geom became a primitive: its kind and the distance (m) of the mesh's
    surface from the primitive's (RMS, 95th percentile, largest)."""

    link: str
    geom: str
    kind: str
    rms_m: float
    p95_m: float
    max_m: float


def prepare_user_model(spec: mujoco.MjSpec, scene: Scene, urdf: bool) -> None:
    """A URDF's sensor site and flange as sites at their links' frames, its links kept apart, a physics
    step, and its touchable links' collision geoms (named ``<link>_<k>`` when nameless) in the surface group."""
    if urdf:
        spec.compiler.fusestatic = False  # MuJoCo's URDF default merges joint-less links (the base) away
        # a URDF sets no physics step: ~0.5 ms, a whole number of steps per sensor sample
        rate = sample_rate_hz(scene)
        spec.option.timestep = 1.0 / (rate * max(1, round(1.0 / (rate * 5e-4))))
        for name in (scene.sensor.site if scene.sensor is not None else None, scene.robot.flange):
            if name and spec.site(name) is None and spec.body(name) is not None:
                spec.body(name).add_site(name=name)
    touchable = {t.link for t in scene.touchable}
    count: dict[str, int] = {}
    for geom in spec.geoms:
        link = geom.parent.name
        if link not in touchable:
            continue
        k = count[link] = count.get(link, -1) + 1
        if not geom.name:
            geom.name = f"{link}_{k}"
        if urdf and (geom.contype or geom.conaffinity):
            geom.group = SURFACE_GROUP
            geom.contype, geom.conaffinity = 1, 2  # touches the world's obstacles, never the arm itself


def touchable_meshes(spec: mujoco.MjSpec, scene: Scene) -> list[mujoco.MjsGeom]:
    touchable = {t.link for t in scene.touchable}
    return [g for g in spec.geoms if g.type == mujoco.mjtGeom.mjGEOM_MESH and g.group == SURFACE_GROUP
            and g.parent.name in touchable]


def fit_mesh_surfaces(spec: mujoco.MjSpec, scene: Scene) -> tuple[MeshFit, ...]:
    """Replace every touchable mesh geom of ``spec`` by its best-fitting primitive (in place); the fits.
    Fitted once per process and robot file (a file changed on disk is fitted again)."""
    meshes = touchable_meshes(spec, scene)
    if not meshes:
        return ()
    path = scene.robot.model_path
    key = (str(path), path.stat().st_mtime_ns, tuple(g.name for g in meshes))
    if key not in _FITTED:
        _FITTED[key] = _best_fits(spec, [g.name for g in meshes])
    best = _FITTED[key]
    for geom in meshes:
        _, fit, size, pos, quat = best[geom.name]
        geom.type = next(t for t, k in _KINDS.items() if k == fit.kind)
        geom.meshname = ""
        geom.size, geom.pos, geom.quat = size, pos, quat
    return tuple(best[g.name][1] for g in meshes)


_FITTED: dict[tuple, dict] = {}


def _best_fits(spec: mujoco.MjSpec, names: list[str]) -> dict[str, tuple]:
    """Per geom: (rms, MeshFit, size, pos, quat) of the best primitive."""
    m_mesh = spec.compile()
    samples = _mesh_samples(m_mesh, names)  # (points in the body frame) per geom
    best: dict[str, tuple[float, MeshFit, np.ndarray, np.ndarray, np.ndarray]] = {}
    for aabb in (False, True):
        for gtype, kind in _KINDS.items():
            for group, m in _trials(spec, names, gtype, aabb):
                for name in group:
                    g = m.geom(name).id
                    d = _distances(kind, m.geom_size[g], m.geom_pos[g], m.geom_quat[g], samples[names.index(name)])
                    fit = MeshFit(link=m.body(int(m.geom_bodyid[g])).name, geom=name, kind=kind,
                                  rms_m=float(np.sqrt(np.mean(d**2))), p95_m=float(np.quantile(d, 0.95)),
                                  max_m=float(d.max()))
                    if name not in best or fit.rms_m < best[name][0]:
                        best[name] = (fit.rms_m, fit, m.geom_size[g].copy(), m.geom_pos[g].copy(),
                                      m.geom_quat[g].copy())
    for name, (size, pos, quat, kind) in _axial_boxes(m_mesh, names):
        d = _distances(kind, size, pos, quat, samples[names.index(name)])
        rms = float(np.sqrt(np.mean(d**2)))
        if name not in best or rms < best[name][0]:
            link = m_mesh.body(int(m_mesh.geom_bodyid[m_mesh.geom(name).id])).name
            fit = MeshFit(link=link, geom=name, kind=kind, rms_m=rms,
                          p95_m=float(np.quantile(d, 0.95)), max_m=float(d.max()))
            best[name] = (rms, fit, size, pos, quat)
    unfitted = [n for n in names if n not in best]
    if unfitted:
        raise ValueError(f"no primitive fits the meshes of {', '.join(unfitted)}")
    return best


def _trials(spec: mujoco.MjSpec, names: list[str], gtype, aabb: bool):
    """(geoms, compiled model) with ``names`` made ``gtype`` and fitted by MuJoCo: all at once, or one
    by one where a fit is degenerate (a capsule around a flat disc has no length)."""
    def compiled(group: list[str]) -> mujoco.MjModel:
        trial = spec.copy()
        trial.compiler.fitaabb = aabb
        for name in group:
            trial.geom(name).type = gtype
        return trial.compile()
    try:
        yield names, compiled(names)
        return
    except ValueError:
        pass
    for name in names:
        try:
            yield [name], compiled([name])
        except ValueError:
            continue


_AXES = {0: np.array([0.5, 0.5, 0.5, 0.5]), 1: np.array([0.5, -0.5, -0.5, -0.5]), 2: np.array([1.0, 0.0, 0.0, 0.0])}


def _axial_boxes(m: mujoco.MjModel, names: list[str]):
    """Cylinders and capsules on the mesh's bounding box along each of its three principal axes (MuJoCo
    fits along the principal z only, which for a flat disc is a diameter): (geom, (size, pos, quat, kind))."""
    for name in names:
        g = m.geom(name).id
        mesh = int(m.geom_dataid[g])
        vert = m.mesh_vert[int(m.mesh_vertadr[mesh]):int(m.mesh_vertadr[mesh]) + int(m.mesh_vertnum[mesh])]
        lo, hi = vert.min(axis=0).astype(float), vert.max(axis=0).astype(float)
        half, pos = (hi - lo) / 2, m.geom_pos[g] + quat_matrix(m.geom_quat[g]) @ ((hi + lo) / 2)
        for axis, turn in _AXES.items():  # turn: the geom's z onto this principal axis
            quat = np.empty(4)
            mujoco.mju_mulQuat(quat, m.geom_quat[g], turn)
            r, h = max(np.delete(half, axis)), half[axis]
            yield name, (np.array([r, h, 0.0]), pos, quat, "cylinder")
            if h > r:
                yield name, (np.array([r, h - r, 0.0]), pos, quat, "capsule")


def _mesh_samples(m: mujoco.MjModel, names: list[str]) -> list[np.ndarray]:
    """Points spread over each mesh geom's triangles by area (seeded), in its body's frame."""
    rng = np.random.default_rng(0)
    out = []
    for name in names:
        g = m.geom(name).id
        mesh = int(m.geom_dataid[g])
        v0, nv = int(m.mesh_vertadr[mesh]), int(m.mesh_vertnum[mesh])
        f0, nf = int(m.mesh_faceadr[mesh]), int(m.mesh_facenum[mesh])
        vert = m.mesh_vert[v0:v0 + nv].astype(float)
        tri = vert[m.mesh_face[f0:f0 + nf]]
        area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        pick = rng.choice(nf, size=_SAMPLES, p=area / area.sum())
        u, v = rng.random((2, _SAMPLES))
        flip = u + v > 1.0
        u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
        t = tri[pick]
        local = t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])
        out.append(local @ quat_matrix(m.geom_quat[g]).T + m.geom_pos[g])  # the mesh's frame is the geom's
    return out


def _distances(kind: str, size: np.ndarray, pos: np.ndarray, quat: np.ndarray, points: np.ndarray) -> np.ndarray:
    rot = quat_matrix(quat)
    local = (points - pos) @ rot
    return np.linalg.norm(project(kind, size, local) - local, axis=1)


def quat_matrix(quat) -> np.ndarray:
    """The 3 x 3 rotation of a MuJoCo quaternion (w, x, y, z)."""
    r = np.empty(9)
    mujoco.mju_quat2Mat(r, np.asarray(quat, dtype=float))
    return r.reshape(3, 3)
