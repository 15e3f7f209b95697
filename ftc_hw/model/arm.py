"""The arm model on MuJoCo: kinematics, link surfaces, Jacobians, predicted sensor wrench and joint torques.

Frames (docs/conventions.md): ``base`` is the model's world frame; ``sensor`` is the scene's sensor site;
``<link>`` is a body's frame. Poses are 4x4 homogeneous matrices named ``base_T_<frame>``.
"""
from __future__ import annotations

import copy
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from ..scene import CompensationLevel, Scene, SceneError
from .build import (
    FORCE_SENSOR,
    TORQUE_SENSOR,
    Payload,
    add_ft_sensors,
    attach_payload,
    descends,
    ft_site_id,
    load_spec_and_fits,
)
from .inertials import body_params, set_body_params
from .joint_map import JointMap
from .mesh_fit import SURFACE_GROUP

GRAVITY_OFF = int(mujoco.mjtDisableBit.mjDSBL_GRAVITY)

GEOM_KINDS = {
    mujoco.mjtGeom.mjGEOM_PLANE: "plane",
    mujoco.mjtGeom.mjGEOM_SPHERE: "sphere",
    mujoco.mjtGeom.mjGEOM_CAPSULE: "capsule",
    mujoco.mjtGeom.mjGEOM_ELLIPSOID: "ellipsoid",
    mujoco.mjtGeom.mjGEOM_CYLINDER: "cylinder",
    mujoco.mjtGeom.mjGEOM_BOX: "box",
}


@dataclass(frozen=True)
class Contact:
    """A point contact: ``force`` (N, base frame) applied to the arm at ``point`` (m, base frame) of ``link``."""

    link: str
    point: np.ndarray
    force: np.ndarray


@dataclass(frozen=True)
class Surface:
    """One primitive of a link's surface, in MuJoCo's size convention.

    sphere (r), capsule and cylinder (r, half-length along local z), ellipsoid (a, b, c),
    box (half-sizes), plane (z = 0 of the geom frame, normal +z).
    """

    link: str
    geom: str
    kind: str
    size: np.ndarray
    link_T_geom: np.ndarray
    pulls: bool


@dataclass(frozen=True)
class PosedSurface:
    surface: Surface
    base_T_geom: np.ndarray


def pose(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = rotation
    out[:3, 3] = translation
    return out


class ArmModel:
    """A scene's robot as MuJoCo sees it, with the scene's gravity and sensor.

    Not thread-safe: it owns one ``MjData`` scratch buffer. Make one per thread.
    """

    def __init__(self, scene: Scene, payload: Payload | None = None,
                 inertials: Mapping[str, np.ndarray] | None = None) -> None:
        """``inertials``: identified corrections to bodies' 10 standard parameters (:mod:`.inertials`)."""
        self.scene = scene
        self.payload = payload
        self.inertials = dict(inertials or {})
        spec, self.mesh_fits = load_spec_and_fits(scene)
        if scene.sensor is not None:  # a scene without an F/T sensor (joint signals only) models none
            add_ft_sensors(spec, scene)
        if payload is not None:
            attach_payload(spec, scene, payload)
        self.model = spec.compile()
        m = self.model
        # Predictions are rigid-body dynamics only: no contacts, joint limits, friction loss or damping
        # (joint friction is the scene's friction model, applied where joint torques are compared).
        m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT | mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
        m.dof_damping[:] = 0.0
        m.dof_frictionloss[:] = 0.0
        self.data = mujoco.MjData(m)
        if self.inertials:
            for body, delta in self.inertials.items():
                b = m.body(body).id
                set_body_params(m, b, body_params(m, b) + np.asarray(delta, dtype=float), nearest=True)
            self.set_const()
        # the F/T sensor, if the scene has one (None: the wrench predictions raise a SceneError). A flange
        # sensor's body carries only what hangs beyond it (build.add_ft_sensors): its subtree is its load
        self.site_id = ft_site_id(m, scene)
        self.sensor_body = None if self.site_id is None else int(m.site_bodyid[self.site_id])
        if self.site_id is not None:
            self._force_adr = m.sensor(FORCE_SENSOR).adr[0]
            self._torque_adr = m.sensor(TORQUE_SENSOR).adr[0]
            # the sensor's wrench in sensordata: one gather per frame instead of two slices
            self._wrench_adr = np.r_[self._force_adr:self._force_adr + 3, self._torque_adr:self._torque_adr + 3]

        self.joint_names = scene.robot.joints
        self.n_joints = len(self.joint_names)
        self.joints = JointMap(m, scene)
        if m.nq != len(self.joints.qadr) or m.nv != len(self.joints.dadr):
            raise SceneError(scene.path, "robot.joints",
                             f"the model has {m.nq} position coordinates but the scene sets "
                             f"{len(self.joints.qadr)} ({', '.join(self.joints.model_joints)})")
        self._forces_applied = False
        self.link_names = tuple(m.body(i).name for i in range(1, m.nbody))
        self.surfaces = self._collect_surfaces()
        self.sign = 1.0 if scene.sensor is None else scene.sensor.reading_sign
        # the mass the F/T sensor carries (without one: the whole arm's)
        self.total_mass = float(m.body_subtreemass[0 if self.sensor_body is None else self.sensor_body])
        self._posed = b""  # the q (bytes) whose kinematics the data holds (b"": none known)
        self._sensor_q = b""  # the q (bytes) of _sensor_T, the last base_T_sensor
        self._sensor_T = np.eye(4)

    # -- set-up ---------------------------------------------------------------------------------------
    def _collect_surfaces(self) -> tuple[Surface, ...]:
        m = self.model
        out = []
        for t in self.scene.touchable:
            try:
                body = m.body(t.link)
            except KeyError:
                raise SceneError(self.scene.path, "touchable.link",
                                 f"no body {t.link!r} in {self.scene.robot.model_path.name}") from None
            for g in range(m.ngeom):
                if m.geom_bodyid[g] != body.id or m.geom_group[g] != SURFACE_GROUP:
                    continue
                kind = GEOM_KINDS.get(int(m.geom_type[g]))
                if kind is None:
                    raise SceneError(self.scene.path, "touchable.link",
                                     f"geom {m.geom(g).name!r} of {t.link!r} is not a primitive "
                                     "(sphere, capsule, cylinder, ellipsoid, box, plane)")
                rot = np.empty(9)
                mujoco.mju_quat2Mat(rot, m.geom_quat[g])
                out.append(Surface(link=t.link, geom=m.geom(g).name or f"geom{g}", kind=kind,
                                   size=m.geom_size[g].copy(), link_T_geom=pose(rot.reshape(3, 3), m.geom_pos[g]),
                                   pulls=t.pulls))
            if not any(s.link == t.link for s in out):
                raise SceneError(self.scene.path, "touchable.link",
                                 f"link {t.link!r} has no surface geoms (group {SURFACE_GROUP})")
        return tuple(out)

    def surface_tolerance(self, link: str) -> float:
        """1 sigma (m) of the real shell's distance from the model's surface on ``link``: the scene's
        ``surface_tolerance_m`` and, where the link's surface was fitted to meshes, the fit's RMS."""
        fit = max((f.rms_m for f in self.mesh_fits if f.link == link), default=0.0)
        return math.hypot(self.scene.robot.surface_tolerance, fit)

    def moving_joints(self, body: str | int) -> np.ndarray:
        """Which scene joints move ``body`` (name or id; bool per joint): those with a model joint on it
        or on an ancestor of it."""
        m = self.model
        bid = body if isinstance(body, int) else m.body(body).id
        out = np.zeros(self.n_joints, dtype=bool)
        for jid, joint in zip(self.joints.jnt_ids, self.joints.joint, strict=True):
            out[joint] |= descends(m, bid, int(m.jnt_bodyid[jid]))
        return out

    def joint_limits(self, unlimited: float = np.pi) -> tuple[np.ndarray, np.ndarray]:
        """Each joint's position range (lower, upper), rad; -unlimited..unlimited where the model sets
        none (default -pi..pi: one turn, what pose sampling wants)."""
        return self.joints.limits(self.model, unlimited)

    def set_const(self) -> None:
        """``mj_setConst`` after a change of the model's parameters (it poses the data at qpos0)."""
        mujoco.mj_setConst(self.model, self.data)
        self._posed = b""

    def twin(self) -> ArmModel:
        """This model with MjData of its own: a stage may compute on it (another state, another thread) without
        moving this one's data or its caches. The compiled model is shared: what changes it changes both."""
        out = copy.copy(self)
        out.data = mujoco.MjData(self.model)
        out._posed = out._sensor_q = b""
        out._sensor_T = np.eye(4)
        out._forces_applied = False
        return out

    def _require_ft(self) -> None:
        if self.site_id is None:
            self.scene.require_ft("a predicted sensor wrench")

    # -- state ----------------------------------------------------------------------------------------
    def _set(self, q: Sequence[float] | np.ndarray, qd=None, qdd=None) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        self._posed = b""
        if q.shape != (self.n_joints,):
            raise ValueError(f"q must have {self.n_joints} entries (joints {', '.join(self.joint_names)}), "
                             f"got shape {q.shape}")
        if not math.isfinite(np.add.reduce(q)):  # NaN or Inf anywhere (add.reduce: sum without its wrapper)
            raise ValueError("q holds NaN or Inf")
        d = self.data
        jm = self.joints
        jm.set_qpos(q, d.qpos)
        # every dof is set by an arm joint (checked in __init__): no other entries to clear
        if qd is None:
            d.qvel[:] = 0.0
        else:
            jm.set_dofs(np.asarray(qd, dtype=float), d.qvel)
        if qdd is None:
            d.qacc[:] = 0.0
        else:
            jm.set_dofs(np.asarray(qdd, dtype=float), d.qacc)
        if self._forces_applied:
            d.xfrc_applied[:] = 0.0
            self._forces_applied = False
        return q

    def kinematics(self, q) -> dict[str, np.ndarray]:
        """``base_T_<link>`` for every body at joint angles q (rad)."""
        self._set(q)
        mujoco.mj_kinematics(self.model, self.data)
        d = self.data
        return {name: pose(d.xmat[i + 1].reshape(3, 3), d.xpos[i + 1]) for i, name in enumerate(self.link_names)}

    def body_poses(self, q) -> tuple[np.ndarray, np.ndarray]:
        """Every body's position (nbody, 3) and quaternion (nbody, 4) in the base frame at joint
        angles q (MuJoCo's arrays: valid until the model's next computation)."""
        self._set(q)
        mujoco.mj_kinematics(self.model, self.data)
        return self.data.xpos, self.data.xquat

    def base_T_site(self, q, site: str) -> np.ndarray:
        self._set(q)
        mujoco.mj_kinematics(self.model, self.data)
        sid = self.model.site(site).id
        return pose(self.data.site_xmat[sid].reshape(3, 3), self.data.site_xpos[sid])

    def base_T_sensor(self, q) -> np.ndarray:
        """``base_T_site`` of the sensor, read-only, computed once for a q: a contact frame's solve, its
        event's uncertainty and its line of action all ask for it at the frame's q (three kinematics
        passes an event before, measured by ``ftc bench pipeline``)."""
        q = np.asarray(q, dtype=float)
        key = q.tobytes()
        if self.site_id is None:
            return self._sensor_T  # the identity: no sensor, its frame is the base frame
        if key != self._sensor_q:
            self._require_ft()
            if key != self._posed:  # else the frame's arm_loads has posed the data at q
                self._set(q)
                mujoco.mj_kinematics(self.model, self.data)
                self._posed = key
            out = pose(self.data.site_xmat[self.site_id].reshape(3, 3), self.data.site_xpos[self.site_id])
            out.flags.writeable = False
            self._sensor_T, self._sensor_q = out, key
        return self._sensor_T

    def posed_surfaces(self, q) -> list[PosedSurface]:
        """Every touchable primitive with its pose ``base_T_geom`` at q."""
        links = self.kinematics(q)
        return [PosedSurface(s, links[s.link] @ s.link_T_geom) for s in self.surfaces]

    def jacobian(self, q, link: str, point) -> np.ndarray:
        """Positional Jacobian (3 x n, m/rad) of the point of ``link`` at ``point`` (base frame) at q."""
        self._set(q)
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_comPos(self.model, self.data)
        jac = np.zeros((3, self.model.nv))
        mujoco.mj_jac(self.model, self.data, jac, None, np.asarray(point, dtype=float), self.model.body(link).id)
        return self.joints.jacobian(jac)

    def twist_jacobian(self, q, link: str, point) -> tuple[np.ndarray, np.ndarray]:
        """The positional (3 x n, m/rad) and rotational (3 x n, rad/rad) Jacobians of ``link`` at ``point``
        (base frame) at q, from one posing (a point ``r`` away moves at ``J_p + J_r x r``)."""
        self._set(q)
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_comPos(self.model, self.data)
        jacp, jacr = np.zeros((3, self.model.nv)), np.zeros((3, self.model.nv))
        mujoco.mj_jac(self.model, self.data, jacp, jacr, np.asarray(point, dtype=float), self.model.body(link).id)
        return self.joints.jacobian(jacp), self.joints.jacobian(jacr)

    def contact_acceleration(self, q, link: str, point, force) -> np.ndarray:
        """The joint accelerations (rad/s^2) a force (N, base frame) on ``link`` at ``point`` adds at
        once, before any joint controller reacts to the motion it causes: M(q)^-1 J^T f."""
        jac = self.jacobian(q, link, point)
        return self._solve_m(jac.T @ np.asarray(force, dtype=float))

    def torque_acceleration(self, q, tau) -> np.ndarray:
        """The joint accelerations (rad/s^2) joint torques tau (N m) add at q: M(q)^-1 tau."""
        self._set(q)
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_comPos(self.model, self.data)
        return self._solve_m(np.asarray(tau, dtype=float))

    def _solve_m(self, tau: np.ndarray) -> np.ndarray:
        """M^-1 tau at the kinematics already computed (mj_kinematics, mj_comPos)."""
        m, d = self.model, self.data
        mujoco.mj_crb(m, d)
        if self.joints.coupled:  # the scene joints' mass matrix C^T M C
            mass = np.zeros((m.nv, m.nv))
            mujoco.mj_fullM(m, d, mass)
            c = self.joints.matrix
            return np.linalg.solve(c.T @ mass @ c, tau)
        mujoco.mj_factorM(m, d)
        full = np.zeros(m.nv)
        full[self.joints.dadr] = tau
        out = np.zeros(m.nv)
        mujoco.mj_solveM(m, d, out.reshape(1, -1), full.reshape(1, -1))
        return out[self.joints.dadr]

    # -- predictions ----------------------------------------------------------------------------------
    def predicted_wrench(self, q, qd=None, qdd=None, level: CompensationLevel = "dynamics",
                         contacts: Iterable[Contact] = ()) -> np.ndarray:
        """The wrench the sensor reports (sensor frame, the scene's sign convention) for this state.

        ``level`` says which arm loads are included: ``bias`` none (contacts only), ``gravity`` the
        static weight of the arm, ``dynamics`` weight plus inertial, Coriolis and centrifugal terms
        from (q, qd, qdd). The sensor's bias is not included. A ``SceneError`` where the scene has no sensor.
        """
        self._require_ft()
        self._inverse(q, qd, qdd, level, contacts)
        d = self.data
        out = np.empty(6)
        out[:3] = d.sensordata[self._force_adr:self._force_adr + 3]
        out[3:] = d.sensordata[self._torque_adr:self._torque_adr + 3]
        return self.sign * out

    def joint_torques(self, q, qd=None, qdd=None, level: CompensationLevel = "dynamics",
                      contacts: Iterable[Contact] = ()) -> np.ndarray:
        """Joint torques (N m) the motors must apply for this motion with these contacts (M qdd + c - J^T p)."""
        contacts = list(contacts)
        self._inverse(q, qd, qdd, level, ())
        tau = self.joints.from_dofs(self.data.qfrc_inverse)
        for c in contacts:
            tau -= self.jacobian(q, c.link, c.point).T @ np.asarray(c.force, dtype=float)
        return tau

    def arm_loads(self, q, qd=None, qdd=None, level: CompensationLevel = "dynamics",
                  joint_torques: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
        """The arm's own load on the sensor (sensor frame, scene convention) and, if asked, the joint
        torques (N m) it needs, computing only what ``level`` asks for: ``bias`` nothing (zeros),
        ``gravity`` the static weight from the subtree's mass and centre of mass (plus MuJoCo's
        recursive Newton-Euler at rest for the joint torques), ``dynamics`` MuJoCo's inverse dynamics.
        """
        m, d = self.model, self.data
        if self.site_id is None:
            self._require_ft()
        if level == "bias":
            return np.zeros(6), (np.zeros(self.n_joints) if joint_torques else None)
        if level == "dynamics":
            self._inverse(q, qd, qdd, "dynamics", ())
            tau = self.joints.from_dofs(d.qfrc_inverse) if joint_torques else None
            return self.sign * d.sensordata[self._wrench_adr], tau
        if level != "gravity":
            raise ValueError(f"level must be bias, gravity or dynamics, got {level!r}")
        self._posed = self._set(q).tobytes()
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        b = self.sensor_body
        weight = self.total_mass * np.asarray(self.scene.gravity, dtype=float)  # the load on the arm, base frame
        com = d.subtree_com[b]
        site_pos = d.site_xpos[self.site_id]
        rot = d.site_xmat[self.site_id].reshape(3, 3)
        # base_on_arm about the sensor origin: minus the weight and its moment
        f = -weight
        t = -np.cross(com - site_pos, weight)
        out = np.concatenate([rot.T @ f, rot.T @ t])
        tau = None
        if joint_torques:
            m.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_GRAVITY)
            mujoco.mj_comVel(m, d)
            res = np.zeros(m.nv)
            mujoco.mj_rne(m, d, 0, res)
            tau = self.joints.from_dofs(res)
        return self.sign * out, tau

    def wrench_qdd_jacobian(self) -> np.ndarray:
        """d(sensor wrench)/d(qdd) (6 x n, sensor frame, scene convention) at the state of the last
        ``arm_loads``/``predicted_wrench`` call: the subtree's linear momentum Jacobian (mass times
        the centre-of-mass Jacobian) and its angular one about the sensor origin. The wrench is
        linear in qdd, so this maps an acceleration error to the wrench error it causes."""
        self._require_ft()
        m, d = self.model, self.data
        b = self.sensor_body
        jcom = np.zeros((3, m.nv))
        mujoco.mj_jacSubtreeCom(m, d, jcom, b)
        ang = np.zeros((3, m.nv))
        mujoco.mj_angmomMat(m, d, ang, b)  # about the subtree's centre of mass
        lin = self.total_mass * jcom
        arm = d.subtree_com[b] - d.site_xpos[self.site_id]
        rot = d.site_xmat[self.site_id].reshape(3, 3)
        g = np.empty((6, self.n_joints))
        lin_q = self.joints.jacobian(lin)
        g[:3] = rot.T @ lin_q
        skew = np.array([[0.0, -arm[2], arm[1]], [arm[2], 0.0, -arm[0]], [-arm[1], arm[0], 0.0]])
        g[3:] = rot.T @ (skew @ lin_q + self.joints.jacobian(ang))
        return self.sign * g

    def _inverse(self, q, qd, qdd, level: CompensationLevel, contacts: Iterable[Contact]) -> None:
        if level not in ("bias", "gravity", "dynamics"):
            raise ValueError(f"level must be bias, gravity or dynamics, got {level!r}")
        m, d = self.model, self.data
        q = self._set(q, qd, qdd) if level == "dynamics" else self._set(q)
        opt = m.opt
        flags = opt.disableflags
        want = flags | GRAVITY_OFF if level == "bias" else flags & ~GRAVITY_OFF
        if want != flags:
            opt.disableflags = want
        contacts = contacts if isinstance(contacts, tuple) else tuple(contacts)
        if contacts:
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            for c in contacts:
                apply_point_force(m, d, c.link, c.point, c.force)
            self._forces_applied = True
        mujoco.mj_inverse(m, d)
        self._posed = q.tobytes()  # mj_inverse runs the kinematics

    # -- frames ---------------------------------------------------------------------------------------
    def wrench_sensor_to_base(self, q, wrench_sensor) -> np.ndarray:
        """Re-express a sensor-frame wrench (about the sensor origin) in the base frame about the base origin.

        The sign convention is kept: this only changes frame and reference point.
        """
        b_T_s = self.base_T_sensor(q)
        r, t = b_T_s[:3, :3], b_T_s[:3, 3]
        w = np.asarray(wrench_sensor, dtype=float)
        f = r @ w[:3]
        return np.concatenate([f, r @ w[3:] + np.cross(t, f)])


def apply_point_force(model: mujoco.MjModel, data: mujoco.MjData, link: str, point, force) -> None:
    """Add a force (N, world frame) at a world point to ``data.xfrc_applied`` of ``link``.

    ``xfrc_applied`` takes the torque about the body's centre of mass, hence the moment arm from xipos.
    Needs ``mj_kinematics`` to have run for the current qpos.
    """
    bid = model.body(link).id
    f = np.asarray(force, dtype=float)
    data.xfrc_applied[bid, :3] += f
    data.xfrc_applied[bid, 3:] += np.cross(np.asarray(point, dtype=float) - data.xipos[bid], f)


def _primitive_radius(kind: str, size: np.ndarray) -> float:
    """The radius of a sphere about the geom's origin that holds the primitive (inf for a plane)."""
    r, h = float(size[0]), float(size[1])
    if kind == "sphere":
        return r
    if kind == "capsule":
        return r + h
    if kind == "cylinder":
        return math.hypot(r, h)
    if kind == "box":
        return float(np.linalg.norm(size[:3]))
    if kind == "ellipsoid":
        return float(np.max(size[:3]))
    return math.inf


def link_reach(model: ArmModel) -> dict[str, float]:
    """Per touchable link, the radius (m) of a sphere about the link's origin that holds all its
    surface primitives: the link's size, as far as a point on it can be uncertain."""
    out: dict[str, float] = {}
    for s in model.surfaces:
        r = float(np.linalg.norm(s.link_T_geom[:3, 3])) + _primitive_radius(s.kind, s.size)
        out[s.link] = max(out.get(s.link, 0.0), r)
    return out
