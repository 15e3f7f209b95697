"""The physics world: a MuJoCo simulation of a scene that produces device signals and ground truth.

One physics step is ``model.opt.timestep`` (0.5 ms in the built-ins). Each step is split in
``mj_step1`` / ``mj_step2`` so that the recorded state (q, qd, qdd), the joint torques, the sensor
wrench and the contacts all belong to the same instant: the state before the integration.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator
from dataclasses import dataclass, field

import mujoco
import numpy as np

from ftc_hw.geometry import ray_distance
from ftc_hw.model import (
    FORCE_SENSOR,
    TORQUE_SENSOR,
    JointMap,
    Payload,
    add_ft_sensors,
    arm_bodies,
    attach_payload,
    ft_site_id,
    sample_rate_hz,
)
from ftc_hw.model.arm import GEOM_KINDS
from ftc_hw.model.true_arm import compile_true_arm, true_arm_spec
from ftc_hw.scene import Scene

from .joint_sensing import JointFriction, JointThermal, JointTorqueSensors, MotorModel, friction_torques
from .sensor_model import FTSensorModel, SensorReading
from .trajectory import Glide, Hold, Trajectory
from .true_shell import mesh_point, shell_meshes

_MESH_REACH_M = 0.1  # how far past the hull's contact the line may meet the mesh (the hull's hollows)


def _run_view(a: np.ndarray, index: np.ndarray) -> np.ndarray | None:
    """``a[index]`` as a view when ``index`` is one ascending run of addresses, else None."""
    lo = int(index[0]) if len(index) else 0
    return a[lo:lo + len(index)] if np.array_equal(index, np.arange(lo, lo + len(index))) else None


@dataclass(frozen=True)
class Probe:
    """A scripted probe pressing a point of a link: a trapezoid force profile, fixed direction."""

    link: str
    point_link: np.ndarray  # m, in the link's body frame (the probe tip moves with the link)
    direction: np.ndarray  # unit vector, base frame, of the force applied to the arm
    magnitude: float  # N at the plateau
    t_start: float  # s, scenario time (World.start_script)
    ramp_s: float = 0.05
    hold_s: float = 0.2
    normal_link: np.ndarray | None = None  # outward surface normal at the point, link frame (None: -direction)
    geom: str | None = None  # the surface geom the point is on (its shell offset applies)
    on_true_shell: bool = False  # point_link was moved onto the true arm's mesh shell (no offset applies)
    smooth: bool = False  # ramps as raised cosines (a hand's force: no jump in its rate), else linear
    label: str = ""  # the scripted contact's kind in the truth ("guidance", ...; "": none said)

    @property
    def t_end(self) -> float:
        return self.t_start + 2 * self.ramp_s + self.hold_s

    def magnitude_at(self, t: float) -> float:
        u = t - self.t_start
        if u <= 0 or t >= self.t_end:
            return 0.0
        if u < self.ramp_s:
            return self.magnitude * self._ramp(u / self.ramp_s)
        if u <= self.ramp_s + self.hold_s:
            return self.magnitude
        return self.magnitude * self._ramp((self.t_end - t) / self.ramp_s)

    def _ramp(self, x: float) -> float:
        return 0.5 - 0.5 * math.cos(math.pi * x) if self.smooth else x


@dataclass(frozen=True)
class Obstacle:
    """A sphere the moving arm can hit, mounted on a spring along ``axis`` (a compliant object)."""

    position: np.ndarray  # m, base frame
    radius: float = 0.03
    axis: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0]))
    stiffness: float = 2000.0  # N/m
    damping: float = 60.0  # N s/m
    mass: float = 0.3
    until_s: float = math.inf  # s, scenario time: withdrawn (no longer touchable) from then on, once nothing touches it
    from_s: float = 0.0  # s, scenario time: touchable from then on (before: not there)
    label: str = ""  # the scripted contact's kind in the truth ("clamping", "impact", ...; "": none said)


@dataclass(frozen=True)
class ScenarioSetup:
    trajectory: Trajectory
    probes: tuple[Probe, ...] = ()
    obstacles: tuple[Obstacle, ...] = ()
    payload: Payload | None = None


@dataclass(frozen=True)
class ContactTruth:
    link: str
    point: np.ndarray  # m, base frame
    force: np.ndarray  # N, base frame, applied to the arm
    source: str  # "probe" or "obstacle"
    label: str = ""  # the scripted contact's kind ("clamping", "guidance", "impact"; "": none said)


@dataclass(frozen=True)
class WorldState:
    t: float  # s since the start
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray  # motor torques at the joints, N m
    current: np.ndarray  # motor currents, A (noise-free: the joint torques through the motors' model)
    wrench: np.ndarray | None  # noise-free F/T wrench, no bias (sensor frame, scene convention); None: no F/T sensor
    contacts: tuple[ContactTruth, ...]
    tau_j: np.ndarray | None = None  # N m: the torque each joint transmits (motor torque less the friction
    # applied this step: what a link-side joint torque sensor reads, noise-free); None: the scene has no such sensors


class World:
    """A scene simulated in MuJoCo under joint control, with scripted contacts and the scene's sensing:
    its F/T sensor (if any: at its base or at the flange), motor currents, joint torque sensors (if any).

    Samples come at :attr:`sample_rate_hz` (``ftc_hw.model.sample_rate_hz``: the F/T sensor's rate; without
    one the joint torque sensors', else the arm device's ``frequency``, else 1000 Hz); the joint state is
    there at every physics step."""

    def __init__(self, scene: Scene, setup: ScenarioSetup, seed: int = 0, noise: bool = True) -> None:
        self.scene = scene
        self.setup = setup
        self.rng = np.random.default_rng(seed)
        self.noise = noise
        spec = true_arm_spec(scene, shell="collide" if setup.obstacles else "rays" if setup.probes else "none")
        add_ft_sensors(spec, scene)
        if setup.payload is not None:
            attach_payload(spec, scene, setup.payload)
        self._obstacle_bodies = [self._add_obstacle(spec, i, o) for i, o in enumerate(setup.obstacles)]
        self._add_couplings(spec, scene)
        self.model = m = compile_true_arm(scene, spec)
        # (geom id, spec) of the obstacles still to be withdrawn
        self._to_withdraw = [(m.geom(f"{b}_geom").id, o) for b, o in zip(self._obstacle_bodies, setup.obstacles,
                                                                            strict=True) if math.isfinite(o.until_s)]
        # (geom id, spec, contype, conaffinity) of the obstacles still to come: not touchable until then
        self._to_appear = [(g, o, int(m.geom_contype[g]), int(m.geom_conaffinity[g]))
                           for g, o in ((m.geom(f"{b}_geom").id, o) for b, o in zip(self._obstacle_bodies,
                                                                                     setup.obstacles, strict=True))
                           if o.from_s > 0.0]
        for g, _, _, _ in self._to_appear:
            m.geom_contype[g] = m.geom_conaffinity[g] = 0
        self._geom_label = {m.geom(f"{b}_geom").id: o.label for b, o in zip(self._obstacle_bodies, setup.obstacles,
                                                                             strict=True) if o.label}
        self._script_t0: float | None = 0.0  # world time of scenario time 0; None: the script is held
        self.data = mujoco.MjData(m)
        r, w = scene.robot, scene.world
        self.joints = jm = JointMap(m, scene)
        # each scene joint's friction on the dof its motor drives (a coupling's first driven joint: the
        # others are tied to it), scaled by the gears' temperature where the world says so
        viscous = r.friction_viscous if w.friction_viscous is None else w.friction_viscous
        coulomb = r.friction_coulomb if w.friction_coulomb is None else w.friction_coulomb
        ratio = jm.ratio[jm.lead]
        stribeck = None if w.friction_stribeck is None or not np.any(w.friction_stribeck) else (
            w.friction_stribeck / np.abs(ratio), w.stribeck_velocity * np.abs(ratio))
        self.friction = JointFriction(m, jm, viscous, coulomb, stribeck, w.friction_per_K)
        dofs = self.friction.dofs
        self.torque_constant = r.torque_constant if w.torque_constant is None else w.torque_constant
        self.motors = MotorModel(scene, self.torque_constant)
        self.thermal = JointThermal(scene.n_joints, w) if w.joint_thermal else None
        if self.thermal is not None:
            self.motors.set_temperature(self.thermal.rise)
        self.joint_torque_sensors = None if scene.joint_torque is None else JointTorqueSensors(
            scene.joint_torque, w, self.rng, noise)
        # MuJoCo's friction loss is a soft constraint: its default softness lets joints creep at a
        # fraction of the friction torque. The stiffest stable setting makes it Coulomb-like.
        m.dof_solref[dofs, 0] = 2.0 * m.opt.timestep
        # The impedance matters too: at the default (0.9) a light joint (a bare wrist) slips under a
        # fraction of its friction torque, so the motor current falls short of friction by up to half.
        m.dof_solimp[dofs, 0] = 0.999
        m.dof_solimp[dofs, 1] = 0.9999
        mujoco.mj_setConst(m, self.data)  # the differences applied to the compiled model reach its constants
        site = ft_site_id(m, scene)
        self._fadr = None if site is None else m.sensor(FORCE_SENSOR).adr[0]
        self._tadr = None if site is None else m.sensor(TORQUE_SENSOR).adr[0]
        self._sign = 1.0 if scene.sensor is None else scene.sensor.reading_sign
        # contacts' truth: every contact on the arm (a base sensor's subtree, else every arm body)
        obstacles = {m.body(b).id for b in self._obstacle_bodies}
        self._arm_bodies = set(arm_bodies(m, scene)) - obstacles
        # per geom, what the contacts' truth asks of it every step in contact (model lookups cost more)
        self._geom_on_arm = [int(b) in self._arm_bodies for b in m.geom_bodyid]
        self._geom_link = [m.body(int(b)).name for b in m.geom_bodyid]
        self._geom_kind = [GEOM_KINDS.get(int(k)) for k in m.geom_type]
        self._geom_is_mesh = [int(k) == mujoco.mjtGeom.mjGEOM_MESH for k in m.geom_type]
        self.sensor = None if scene.sensor is None else FTSensorModel(scene.sensor, self.rng, noise=noise, world=w)
        self.dt = float(m.opt.timestep)
        self.sample_rate_hz = sample_rate_hz(scene)
        ratio = 1.0 / (self.sample_rate_hz * self.dt)
        if abs(ratio - round(ratio)) > 1e-6 or round(ratio) < 1:
            raise ValueError(f"sample rate {self.sample_rate_hz} Hz is not a divisor of the physics rate "
                             f"{1 / self.dt:g} Hz")
        self.steps_per_sample = int(round(ratio))
        # the first obstacle contact comes in real time: compile (or load) the ray kernel now, not then
        ray_distance("sphere", (1.0,), np.zeros(3), np.eye(3), (-2.0, 0.0, 0.0), (1.0, 0.0, 0.0))
        self.torque_on = True
        self._reference: Trajectory = setup.trajectory
        self._t_ref0 = 0.0
        self._halted_from: tuple[Trajectory, float, float] | None = None  # what a halt interrupted, for resume
        q0, _, _ = self._reference.reference(0.0)
        jm.set_qpos(np.asarray(q0, dtype=float), self.data.qpos)
        mujoco.mj_forward(m, self.data)
        self.probes_off_mesh = 0  # probes of a mesh-shelled link whose ray missed it: pressed on the model
        self.setup = dataclasses.replace(setup, probes=tuple(self._on_true_shell(p) for p in setup.probes))
        self._prepare_step()
        self.steps = 0
        self.state: WorldState = self._step()

    # -- construction -------------------------------------------------------------------------------
    @staticmethod
    def _add_obstacle(spec: mujoco.MjSpec, i: int, o: Obstacle) -> str:
        name = f"ftc_obstacle{i}"
        body = spec.worldbody.add_body(name=name, pos=list(o.position), gravcomp=1.0)
        body.add_joint(name=f"{name}_slide", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=list(o.axis),
                       stiffness=o.stiffness, damping=o.damping)
        body.add_geom(name=f"{name}_geom", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[o.radius, 0, 0],
                      mass=o.mass, contype=2, conaffinity=1, group=2, condim=3, friction=[0.3, 0.005, 0.0001],
                      solref=[0.02, 1.0])
        return name

    @staticmethod
    def _add_couplings(spec: mujoco.MjSpec, scene: Scene) -> None:
        """Joint equality constraints that tie each coupling's driven joints to its first one (the
        pinion's racks), as stiff as the physics step allows."""
        dt = spec.option.timestep
        for c in scene.robot.couplings:
            for name, ratio in zip(c.drives[1:], c.ratios[1:], strict=True):
                eq = spec.add_equality(type=mujoco.mjtEq.mjEQ_JOINT, name1=name, name2=c.drives[0])
                eq.data[:5] = [0.0, ratio / c.ratios[0], 0.0, 0.0, 0.0]
                eq.solref = [2.0 * dt, 1.0]

    def _on_true_shell(self, p: Probe) -> Probe:
        """The probe moved onto its link's mesh shell, where the true arm has one."""
        m, d = self.model, self.data
        body = m.body(p.link).id
        if not shell_meshes(m, body):
            return p
        outward = p.normal_link if p.normal_link is not None else -(d.xmat[body].reshape(3, 3).T @ p.direction)
        point = mesh_point(m, d, body, np.asarray(p.point_link, dtype=float), np.asarray(outward, dtype=float))
        if point is None:
            self.probes_off_mesh += 1
            return p
        return dataclasses.replace(p, point_link=point, on_true_shell=True)

    def _prepare_step(self) -> None:
        """What every step reuses: buffers, and views of MuJoCo's arrays where the scene's joints sit in
        one run of addresses (a fancy index costs more than the arithmetic on six numbers)."""
        m, d, jm = self.model, self.data, self.joints
        self._acc = np.zeros(m.nv)  # only the scene joints' dofs are ever written
        self._inertial = np.zeros(m.nv)
        self._f6 = np.zeros(6)
        plain = not jm.coupled
        self._qpos = _run_view(d.qpos, jm.qadr) if plain else None
        self._qvel = _run_view(d.qvel, jm.dadr) if plain else None
        self._qacc = _run_view(d.qacc, jm.dadr) if plain else None
        self._bias = _run_view(d.qfrc_bias, jm.dadr) if plain else None
        self._inertial_joints = _run_view(self._inertial, jm.dadr) if plain else None
        f, t = self._fadr, self._tadr
        self._ft = d.sensordata[f:f + 6] if f is not None and t == f + 3 else None  # force then torque, one run
        self._friction_dofs = np.zeros(m.nv)  # the joint friction applied at a step (joint torque sensors)
        self._body_id = {p.link: m.body(p.link).id for p in self.setup.probes}
        std = self.scene.robot.current_noise_std
        self._current_noise = std if self.noise and np.any(std > 0) else None

    def _q(self) -> np.ndarray:
        if self._qpos is not None:
            return self._qpos.copy()
        return self.joints.joints_of(self.data.qpos, self.joints.qadr)

    def _joints(self, view: np.ndarray | None, full: np.ndarray) -> np.ndarray:
        return view.copy() if view is not None else self.joints.joints_of(full)

    # -- control ------------------------------------------------------------------------------------
    def halt(self) -> None:
        """Stop the arm where it is (the reflex a stop command triggers): hold the current position.
        The trajectory it interrupted is kept for :meth:`resume` (the first one, when halted twice)."""
        if self._halted_from is None:
            self._halted_from = (self._reference, self._t_ref0, self.data.time)
        self._reference, self._t_ref0 = Hold(self._q()), self.data.time

    def resume(self) -> bool:
        """Continue the trajectory the last halt interrupted from the point it had reached (its time
        shifted by the halt's length); False when nothing was halted."""
        if self._halted_from is None:
            return False
        reference, t_ref0, t_halt = self._halted_from
        self._halted_from = None
        self._reference, self._t_ref0 = reference, t_ref0 + (self.data.time - t_halt)
        return True

    def set_reference(self, trajectory: Trajectory) -> None:
        """Follow another trajectory from now on; its time starts at the current world time."""
        self._halted_from = None
        self._reference = trajectory
        self._t_ref0 = self.data.time

    def hold_script(self) -> None:
        """Scripted events (probes, obstacle withdrawals) stop happening until ``start_script``."""
        self._script_t0 = None

    def start_script(self) -> None:
        """Scenario time 0 is now: scripted events happen at their scenario times from here."""
        self._script_t0 = self.data.time

    def set_goal(self, q_goal, qd=None, horizon_s: float = 0.0) -> None:
        """Hold at ``q_goal`` (rad); with ``qd`` (rad/s) glide on from it for up to ``horizon_s`` (a servo's
        stream of setpoints with their velocity)."""
        q = np.asarray(q_goal, dtype=float).copy()
        if qd is None or horizon_s <= 0.0:
            self.set_reference(Hold(q))
        else:
            self.set_reference(Glide(q, np.asarray(qd, dtype=float).copy(), float(horizon_s)))

    def set_torque(self, on: bool) -> None:
        """Motor torque on (the joint controller runs) or off (the joints are free: gravity acts)."""
        if on and not self.torque_on:
            self.halt()  # a servo holds where it is when its torque comes back on
        self.torque_on = on

    @property
    def t(self) -> float:
        return float(self.data.time)

    # -- stepping -------------------------------------------------------------------------------------
    def _step(self) -> WorldState:
        m, d, r = self.model, self.data, self.scene.robot
        mujoco.mj_step1(m, d)
        t = float(d.time)
        jm = self.joints
        q = self._q()
        qd = self._joints(self._qvel, d.qvel)
        q_ref, qd_ref, qdd_ref = self._reference.reference(t - self._t_ref0)
        acc, inertial = self._acc, self._inertial
        jm.set_dofs(np.asarray(qdd_ref, dtype=float), acc)
        mujoco.mj_mulM(m, d, inertial, acc)
        if self._bias is not None:  # the same sum as from_dofs(qfrc_bias + inertial), on the joints' dofs only
            feedforward = self._bias + self._inertial_joints
        else:
            feedforward = jm.from_dofs(d.qfrc_bias + inertial)
        tau = r.kp * (q_ref - q) + r.kd * (qd_ref - qd) + feedforward
        if not self.torque_on:
            tau = np.zeros_like(tau)
        d.qfrc_applied[:] = 0.0
        jm.to_dofs(tau, d.qfrc_applied)
        stribeck = self.friction.stribeck_force(d.qvel)
        if stribeck is not None:
            d.qfrc_applied[self.friction.dofs] += stribeck
        d.xfrc_applied[:] = 0.0
        ts = None if self._script_t0 is None else t - self._script_t0  # scenario time
        probes = self._press_probes(ts) if ts is not None and self.setup.probes else ()
        mujoco.mj_step2(m, d)
        self.steps += 1
        if self._to_withdraw and ts is not None and any(ts >= o.until_s for _, o in self._to_withdraw):
            self._withdraw_obstacles(ts)
        if self._to_appear and ts is not None and any(ts >= o.from_s for _, o, _, _ in self._to_appear):
            self._place_obstacles(ts)
        wrench = self._wrench()
        current = self.motors.current(tau, q)
        tau_j = None if self.joint_torque_sensors is None else self._transmitted(tau, stribeck)
        if self.thermal is not None and self.thermal.update(t, current):  # for the steps from the next on
            self.friction.apply(self.thermal.rise)
            self.motors.set_temperature(self.thermal.rise)
        contacts = self._obstacle_contacts() if d.ncon else ()
        return WorldState(t=t, q=q, qd=qd, qdd=self._joints(self._qacc, d.qacc), tau=tau, current=current,
                          wrench=wrench, contacts=probes + contacts if probes else contacts, tau_j=tau_j)

    def _wrench(self) -> np.ndarray | None:
        if self._ft is not None:
            return self._sign * self._ft
        if self._fadr is None:
            return None
        d = self.data
        wrench = np.empty(6)
        wrench[:3] = d.sensordata[self._fadr:self._fadr + 3]
        wrench[3:] = d.sensordata[self._tadr:self._tadr + 3]
        return self._sign * wrench

    def _transmitted(self, tau: np.ndarray, stribeck: np.ndarray | None) -> np.ndarray:
        """The torque each joint transmits at the step just taken: the motor torque plus the friction
        MuJoCo applied (damping, friction loss, the Stribeck excess: all against the motion)."""
        fr = friction_torques(self.model, self.data, self._friction_dofs)
        if stribeck is not None:
            fr[self.friction.dofs] += stribeck
        return tau + self.joints.from_dofs(fr)

    def _press_probes(self, ts: float) -> tuple[ContactTruth, ...]:
        """The scripted probes' forces at scenario time ``ts`` on ``xfrc_applied``; their truth."""
        d = self.data
        probes = []
        for p in self.setup.probes:
            mag = p.magnitude_at(ts)
            if mag <= 0.0:
                continue
            bid = self._body_id[p.link]
            rot = d.xmat[bid].reshape(3, 3)
            point = rot @ p.point_link + d.xpos[bid]
            shell = self.scene.world.shell_of(p.geom) if p.geom else self.scene.world.shell_offset
            if shell and not p.on_true_shell:  # the probe meets the true surface, outside the model's
                point = point + shell * (rot @ p.normal_link if p.normal_link is not None else -p.direction)
            force = mag * p.direction
            d.xfrc_applied[bid, :3] += force
            d.xfrc_applied[bid, 3:] += np.cross(point - d.xipos[bid], force)
            probes.append(ContactTruth(p.link, point, force, "probe", p.label))
        return tuple(probes)

    def _withdraw_obstacles(self, ts: float) -> None:
        m, d = self.model, self.data
        touching = {g for i in range(d.ncon) for g in (d.contact[i].geom1, d.contact[i].geom2)}
        keep = []
        for g, o in self._to_withdraw:
            if ts >= o.until_s and g not in touching:  # never mid-contact: a release nobody made
                m.geom_contype[g] = m.geom_conaffinity[g] = 0
            else:
                keep.append((g, o))
        self._to_withdraw = keep

    def _place_obstacles(self, ts: float) -> None:
        m = self.model
        keep = []
        for g, o, contype, conaffinity in self._to_appear:
            # the body's own filter too: MuJoCo's broadphase skips a body none of whose geoms collide
            if ts >= o.from_s:
                m.geom_contype[g], m.geom_conaffinity[g] = contype, conaffinity
                b = m.geom_bodyid[g]
                m.body_contype[b] |= contype
                m.body_conaffinity[b] |= conaffinity
            else:
                keep.append((g, o, contype, conaffinity))
        self._to_appear = keep

    def _obstacle_contacts(self) -> tuple[ContactTruth, ...]:
        m, d = self.model, self.data
        out = []
        f6 = self._f6
        on_arm = self._geom_on_arm
        for i in range(d.ncon):
            c = d.contact[i]
            g1, g2 = c.geom1, c.geom2
            arm2 = on_arm[g2]
            if on_arm[g1] == arm2:
                continue
            mujoco.mj_contactForce(m, d, i, f6)
            force = c.frame.reshape(3, 3).T @ f6[:3]  # world frame; acts on geom2 (normal from geom1 to geom2)
            force_on_arm, arm_geom = (force, g2) if arm2 else (-force, g1)
            label = self._geom_label.get(g1 if arm2 else g2, "") if self._geom_label else ""
            out.append(ContactTruth(self._geom_link[arm_geom], self._on_arm_surface(arm_geom, c.pos, force_on_arm),
                                    force_on_arm, "obstacle", label))
        return tuple(out)

    def _on_arm_surface(self, geom: int, pos: np.ndarray, force: np.ndarray) -> np.ndarray:
        """Where the contact force's line of action enters the arm geom.

        MuJoCo's contact point is midway through the (soft-contact) penetration, a fraction of a mm
        inside the arm; the same line gives the same wrench, and this point is on the surface. A mesh
        collides as its hull, which bridges the mesh's hollows: the point is where the line meets the
        mesh's own triangles (the surface a localizer on the meshes answers with).
        """
        norm = math.sqrt(force.dot(force))  # np.linalg.norm's own sum, without its overhead
        kind, is_mesh = self._geom_kind[geom], self._geom_is_mesh[geom]
        if norm == 0.0 or (kind is None and not is_mesh):
            return pos.copy()
        m, d = self.model, self.data
        u = force / norm
        start = pos - 0.05 * u
        if is_mesh:  # collided as its part's convex hull: the line enters the mesh itself at or past it
            dist = mujoco.mj_rayMesh(m, d, geom, start, u)
            return start + dist * u if 0.0 <= dist <= _MESH_REACH_M else pos.copy()
        dist = ray_distance(kind, m.geom_size[geom], d.geom_xpos[geom], d.geom_xmat[geom], start, u)
        return start + dist * u if 0.0 <= dist <= 0.06 else pos.copy()

    def step(self) -> WorldState:
        self.state = self._step()
        return self.state

    def read_sensor(self, state: WorldState | None = None) -> SensorReading:
        """The F/T sensor's reading of ``state`` (default: the last); a SceneError without an F/T sensor."""
        s = state or self.state
        if self.sensor is None:
            self.scene.require_ft("an F/T reading of the world")
        return self.sensor.read(s.wrench, s.t)

    def read_joint_torques(self, state: WorldState | None = None) -> np.ndarray:
        """The joint torque sensors' reading (N m per joint: offsets, drift, noise, range); zeros where the
        scene has none."""
        s = state or self.state
        if self.joint_torque_sensors is None:
            return np.zeros(len(s.q))
        return self.joint_torque_sensors.read(s.tau_j, None if self.thermal is None else self.thermal.rise)

    def read_current(self, state: WorldState | None = None) -> np.ndarray:
        s = state or self.state
        if self._current_noise is not None:
            return s.current + self.rng.normal(size=s.current.shape) * self._current_noise
        return s.current.copy()

    def run(self, duration: float) -> Iterator[tuple[WorldState, SensorReading | None]]:
        """Advance ``duration`` s, yielding (state, F/T reading; None without an F/T sensor) at the sample rate."""
        n_samples = int(round(duration * self.sample_rate_hz))
        for _ in range(n_samples):
            for _ in range(self.steps_per_sample):
                state = self.step()
            yield state, None if self.sensor is None else self.read_sensor(state)
