"""The world's truth for a contact's effective mass: the true arm's outward surface normal at a true contact
and its mass matrix's effective mass there (``1 / (n^T J M^-1 J^T n)``, ``ftc_hw/model/effective_mass.py``),
at the step the world has just taken (the benches' and tests' reference for the events' ``effective_mass_kg``).
"""
from __future__ import annotations

import mujoco
import numpy as np

from ftc_hw.model.effective_mass import effective_mass, pose_for_inertia
from ftc_hw.sim_devices.world import ContactTruth, World, WorldState
from ftc_hw.sim_devices.world.true_shell import mesh_hit


def true_normal(world: World, contact: ContactTruth, links: set[str]) -> np.ndarray:
    """The true arm's outward unit normal (base frame) at ``contact``, as the world posed it at its last step:
    a probe's mesh shell triangle's (or its primitive's, the shell offset along it), an obstacle's contact
    frame's (MuJoCo's contact between the arm, ``links``, and the obstacle)."""
    m, d = world.model, world.data
    if contact.source == "obstacle":
        best, normal = np.inf, None
        for i in range(d.ncon):
            c = d.contact[i]
            arm = [m.body(int(m.geom_bodyid[g])).name in links for g in (c.geom1, c.geom2)]
            if arm[0] != arm[1]:  # the frame's normal points from geom1 to geom2
                dist = float(np.linalg.norm(c.pos - contact.point))
                if dist < best:
                    best, normal = dist, c.frame[:3] * (1.0 if arm[0] else -1.0)
        if normal is None:
            raise ValueError(f"an obstacle contact on {contact.link} without a MuJoCo contact")
        return np.array(normal)
    body = m.body(contact.link).id
    rot, pos = d.xmat[body].reshape(3, 3), d.xpos[body]
    probe = min((p for p in world.setup.probes if p.link == contact.link),
                key=lambda p: np.linalg.norm(rot @ p.point_link + pos - contact.point))
    if probe.on_true_shell:
        hit = mesh_hit(m, d, body, probe.point_link, probe.normal_link)
        if hit is not None:
            return rot @ hit[1]
    if probe.normal_link is None:  # the probe's normal is its push's line
        return -np.asarray(probe.direction, dtype=float)
    return rot @ (probe.normal_link / np.linalg.norm(probe.normal_link))


def true_mass(world: World, state: WorldState, contact: ContactTruth, normal: np.ndarray,
              data: mujoco.MjData | None = None) -> float:
    """kg: the true arm's effective mass at ``contact``'s point along ``normal`` (base frame), at ``state``'s q
    (``data``: an ``MjData`` of ``world.model`` to pose, not the world's own; default: a new one)."""
    d = data if data is not None else mujoco.MjData(world.model)
    pose_for_inertia(world.model, d, world.joints, state.q)
    return effective_mass(world.model, d, world.joints, world.model.body(contact.link).id, contact.point, normal)
