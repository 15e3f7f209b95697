"""A user's own robot file, written for the tests: the ur5e scene's arm as a URDF whose touchable
links carry triangle meshes (binary STL, 16-sided prisms, boxes and polyhedral domes around the
model's primitives, so a fit cannot be exact), and a scene TOML with the ur5e scene's devices."""
from __future__ import annotations

import struct
from pathlib import Path

import mujoco
import numpy as np

from ftc_hw.model.build import load_spec
from ftc_hw.model.mesh_fit import SURFACE_GROUP
from ftc_hw.scene import load_scene

SIDES = 16


def _stl(path: Path, tris: np.ndarray) -> None:
    with open(path, "wb") as f:
        f.write(b"ftc-hw test mesh".ljust(80, b" "))
        f.write(struct.pack("<I", len(tris)))
        for t in tris:
            n = np.cross(t[1] - t[0], t[2] - t[0])
            n = n / (np.linalg.norm(n) or 1.0)
            f.write(struct.pack("<12fH", *n, *t[0], *t[1], *t[2], 0))


def _prism(r: float, z0: float, z1: float, caps: bool = True) -> list[np.ndarray]:
    a = np.linspace(0.0, 2 * np.pi, SIDES, endpoint=False)
    ring = np.c_[r * np.cos(a), r * np.sin(a)]
    out = []
    for i in range(SIDES):
        j = (i + 1) % SIDES
        p = [np.r_[ring[i], z0], np.r_[ring[j], z0], np.r_[ring[j], z1], np.r_[ring[i], z1]]
        out += [np.array([p[0], p[1], p[2]]), np.array([p[0], p[2], p[3]])]
        if caps:
            out += [np.array([[0, 0, z0], p[1], p[0]]), np.array([[0, 0, z1], p[3], p[2]])]
    return out


def _dome(r: float, z: float, up: bool, rings: int = 4) -> list[np.ndarray]:
    """A polyhedral hemisphere cap of radius r on the plane z (a capsule's end)."""
    a = np.linspace(0.0, 2 * np.pi, SIDES, endpoint=False)
    el = np.linspace(0.0, np.pi / 2, rings + 1)
    s = 1.0 if up else -1.0
    pts = [[np.array([r * np.cos(e) * np.cos(t), r * np.cos(e) * np.sin(t), z + s * r * np.sin(e)]) for t in a]
           for e in el]
    out = []
    for k in range(rings):
        for i in range(SIDES):
            j = (i + 1) % SIDES
            quad = [pts[k][i], pts[k][j], pts[k + 1][j], pts[k + 1][i]]
            tri1, tri2 = np.array([quad[0], quad[1], quad[2]]), np.array([quad[0], quad[2], quad[3]])
            out += [tri1, tri2] if up else [tri1[::-1], tri2[::-1]]
    return out


def _box(h: np.ndarray) -> list[np.ndarray]:
    c = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float) * h
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    return ([np.array([c[a], c[b], c[d]]) for a, b, _, d in faces]
            + [np.array([c[b], c[e], c[d]]) for _, b, e, d in faces])


def _mesh_of(kind: int, size: np.ndarray) -> list[np.ndarray]:
    g = mujoco.mjtGeom
    if kind == g.mjGEOM_CYLINDER:
        return _prism(size[0], -size[1], size[1])
    if kind == g.mjGEOM_CAPSULE:
        return (_prism(size[0], -size[1], size[1], caps=False) + _dome(size[0], size[1], True)
                + _dome(size[0], -size[1], False))
    if kind == g.mjGEOM_BOX:
        return _box(size)
    r = float(np.mean(size))  # ellipsoid, sphere: a 16-sided ball of the mean radius
    return _dome(r, 0.0, True) + _dome(r, 0.0, False)


def _rpy(r: np.ndarray) -> str:
    pitch = -np.arcsin(np.clip(r[2, 0], -1, 1))
    roll, yaw = np.arctan2(r[2, 1], r[2, 2]), np.arctan2(r[1, 0], r[0, 0])
    return f"{roll:.12g} {pitch:.12g} {yaw:.12g}"


def _origin(t: np.ndarray) -> str:
    return f'<origin xyz="{t[0, 3]:.12g} {t[1, 3]:.12g} {t[2, 3]:.12g}" rpy="{_rpy(t[:3, :3])}"/>'


def _pose(pos, quat) -> np.ndarray:
    t = np.eye(4)
    r = np.empty(9)
    mujoco.mju_quat2Mat(r, np.asarray(quat, dtype=float))
    t[:3, :3], t[:3, 3] = r.reshape(3, 3), pos
    return t


def write_ur5e_urdf(folder: Path) -> Path:
    """ur5e as ``folder/ur5e_user.urdf`` with STL meshes in ``folder/meshes``; the scene file's path.
    A URDF joint sits at its child link's origin: each link frame is the model body's frame moved to
    its joint (the DH bodies have their joints off their origins)."""
    scene = load_scene("ur5e")
    m = load_spec(scene).compile()
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    (folder / "meshes").mkdir(parents=True, exist_ok=True)
    shift = {b: _pose(m.jnt_pos[m.body_jntadr[b]], [1, 0, 0, 0]) if m.body_jntnum[b] else np.eye(4)
             for b in range(m.nbody)}
    frame = {b: _pose(d.xpos[b], d.xquat[b]) @ shift[b] for b in range(m.nbody)}  # the link frames, q = 0
    links, joints = [], []
    for b in range(1, m.nbody):
        name, inv = m.body(b).name, np.linalg.inv(shift[b])
        inertia = m.body_inertia[b]
        parts = [f'<inertial>{_origin(inv @ _pose(m.body_ipos[b], m.body_iquat[b]))}'
                 f'<mass value="{m.body_mass[b]:.12g}"/><inertia ixx="{inertia[0]:.12g}" iyy="{inertia[1]:.12g}" '
                 f'izz="{inertia[2]:.12g}" ixy="0" ixz="0" iyz="0"/></inertial>']
        for g in range(m.ngeom):
            if m.geom_bodyid[g] != b or m.geom_group[g] != SURFACE_GROUP:
                continue
            stl = folder / "meshes" / f"{m.geom(g).name}.stl"
            _stl(stl, np.array(_mesh_of(int(m.geom_type[g]), m.geom_size[g])))
            parts.append(f'<collision>{_origin(inv @ _pose(m.geom_pos[g], m.geom_quat[g]))}'
                         f'<geometry><mesh filename="meshes/{stl.name}"/></geometry></collision>')
        links.append(f'<link name="{name}">{"".join(parts)}</link>')
        parent = int(m.body_parentid[b])
        if parent == 0:
            continue
        origin = _origin(np.linalg.inv(frame[parent]) @ frame[b])
        head = f'<parent link="{m.body(parent).name}"/><child link="{name}"/>{origin}'
        if m.body_jntnum[b]:
            j = int(m.body_jntadr[b])
            lo, hi = m.jnt_range[j]
            joints.append(f'<joint name="{m.joint(j).name}" type="revolute">{head}'
                          f'<axis xyz="{" ".join(f"{a:.12g}" for a in m.jnt_axis[j])}"/>'
                          f'<limit lower="{lo:.12g}" upper="{hi:.12g}" effort="150" velocity="3.14"/></joint>')
        else:
            joints.append(f'<joint name="{name}_fixed" type="fixed">{head}</joint>')
    urdf = folder / "ur5e_user.urdf"
    urdf.write_text('<robot name="ur5e_user">\n' + "\n".join(links + joints) + "\n</robot>\n")
    toml = scene.path.read_text()
    toml = toml.replace('model = "ur5e.xml"', 'model = "ur5e_user.urdf"').replace('name = "ur5e"', 'name = "ur5e-user"')
    toml = toml.replace('site = "ft_sensor"', 'site = "base"').replace('flange = "flange"', 'flange = "wrist_3"')
    toml = toml.replace('dbc = "ati_netft_can.dbc"', f'dbc = "{scene.path.parent / "ati_netft_can.dbc"}"')
    toml = toml.replace('vendor_shell = "robosuite-ur5e"\n', "")
    path = folder / "ur5e_user.toml"
    path.write_text(toml)
    return path
