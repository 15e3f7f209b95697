"""``ftc bench isolation``: how often the motor currents pick the right link when the force line
crosses two links.

The arm moves (every joint, so the Coulomb friction's sign is known) while a probe pushes a point
whose force line also crosses another link. The world simulates the motor currents; the pipeline's
residuals (model torque + friction - torque constant x current) give tau_ext, which the solver
scores the candidates with. Without currents such a case must be flagged ``ambiguous``. With them, a
wrong link is *flagged* when the estimate carries any flag (``ambiguous``, ``off_surface``, ...) and
*silently wrong* otherwise.

A case is *discriminable* when the two best candidates' joint-torque signatures differ by more than
4 standard deviations of tau_ext: only then can any method tell them apart from the currents. The
others (bodies moved by the same joints, points near a joint) must stay flagged or be right.

A case is *rigid* when no joint separates the two links (parts welded together; none in the built-in
scenes since dxl-arm models its gripper joint): their torque signatures are identical, so the
currents carry no information on which was touched and only a flag is right. The share the
acceptance speaks of, right with currents, is also given over the *jointed* cases (the others).
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from rich.table import Table

from ftc_hw.bench.report import table_console
from ftc_hw.compensation.pipeline import Compensator
from ftc_hw.compensation.residuals import JointResiduals
from ftc_hw.model import ArmModel, Contact
from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.world import Probe, ScenarioSetup, Sinusoid, World, with_reality
from ftc_hw.sim_devices.world.scenarios import sample_contacts
from ftc_hw.solver import ContactSolver

SCENES = ("ur5e", "dxl-arm")
DISCRIMINABLE_SIGMA = 4.0
EXACT_CHI2 = 1e-6  # a noise-free crossing fits the wrench exactly


def evaluate(scene_name: str, n_cases: int, seed: int, max_discriminable: int | None = None,
             reality: str = "ideal") -> dict:
    """Counts and shares over the two-link cases among ``n_cases`` sampled contacts (stopping early
    once ``max_discriminable`` discriminable ones were seen), in a world of ``reality`` (seeded draw)."""

    scene = load_scene(scene_name)
    world_scene = with_reality(scene, reality, seed)
    model = ArmModel(scene)
    solver = ContactSolver(model)
    residuals = JointResiduals(scene)
    home = np.array(scene.robot.home)
    # every joint (the gripper too) at full speed at t_eval: the sweep's phase puts its peak speed there;
    # the arm starts at rest on the moving reference, settled well before the probe's 0.15 s lead
    t_eval = 0.5
    motion = Sinusoid(home, np.full(scene.n_joints, 0.1), 0.25, phase=-2 * np.pi * 0.25 * t_eval)
    q, _, _ = motion.reference(t_eval)
    f_max = min(60.0, 0.15 * float(scene.sensor.range[:3].min()))
    rng = np.random.default_rng(seed)
    counts = dict.fromkeys(("two_link", "ambiguous_without", "right_without", "right", "flagged", "wrong",
                            "discriminable", "discriminable_right", "other_right", "other_flagged", "other_wrong",
                            "rigid", "rigid_right", "rigid_flagged", "rigid_wrong"), 0)
    link_id = {name: i for i, name in enumerate(solver.links)}
    for sp, force in sample_contacts(model, q, n_cases, rng, 40.0, (0.5 * f_max, f_max)):
        w = model.predicted_wrench(q, level="bias", contacts=[Contact(sp.link, sp.point, force)])
        e = solver.solve(w, q)
        if len({c.link for c in e.candidates if c.chi2 < EXACT_CHI2}) < 2:
            continue  # the line does not cross a second link (near misses of it are no ambiguity)
        counts["two_link"] += 1
        counts["ambiguous_without"] += "ambiguous" in e.flags
        counts["right_without"] += e.link == sp.link and "ambiguous" not in e.flags
        local = np.linalg.inv(model.kinematics(q)[sp.link]) @ np.append(sp.point, 1.0)
        fmag = float(np.linalg.norm(force))
        probe = Probe(sp.link, local[:3], force / fmag, fmag, t_start=t_eval - 0.15, ramp_s=0.05, hold_s=0.3)
        world = World(world_scene, ScenarioSetup(motion, probes=(probe,)), seed=counts["two_link"] + seed * 100_000)
        state = reading = None
        for state, reading in world.run(t_eval):  # noqa: B007 - the last sample is the one we want
            pass
        comp = Compensator(model, "dynamics", bias=scene.sensor.bias)
        ext = comp.external(reading.wrench - scene.sensor.drift_per_s * state.t, state.q, state.qd, state.qdd)
        _, model_tau = model.arm_loads(state.q, state.qd, state.qdd, level="dynamics", joint_torques=True)
        tau_ext, tau_std = residuals.external_torques(model_tau, world.read_current(state), state.qd)
        e2 = solver.solve(ext, state.q, tau_ext=tau_ext, tau_std=tau_std)
        right = e2.link == sp.link
        flagged = not right and bool(e2.flags)  # ambiguous, off_surface, ...: not a silent answer
        counts["right"] += right
        counts["flagged"] += flagged
        counts["wrong"] += not (right or flagged)
        a = e.candidates[0]
        b = next(c for c in e.candidates if c.link != a.link and c.chi2 < EXACT_CHI2)
        if (solver.link_joint[link_id[a.link]] == solver.link_joint[link_id[b.link]]).all():
            counts["rigid"] += 1
            counts["rigid_right"] += right
            counts["rigid_flagged"] += flagged
            counts["rigid_wrong"] += not (right or flagged)
        sig = [-model.joint_torques(q, level="bias", contacts=[Contact(c.link, c.point, c.force)]) for c in (a, b)]
        if np.linalg.norm((sig[0] - sig[1]) / tau_std) > DISCRIMINABLE_SIGMA:
            counts["discriminable"] += 1
            counts["discriminable_right"] += right
        else:
            counts["other_right"] += right
            counts["other_flagged"] += flagged
            counts["other_wrong"] += not (right or flagged)
        if max_discriminable is not None and counts["discriminable"] >= max_discriminable:
            break
    c = counts

    def share(k: str, of: str) -> float:
        return c[k] / c[of] if c[of] else math.nan

    return c | {"right_share": share("right", "two_link"), "wrong_share": share("wrong", "two_link"),
                "discriminable_share": share("discriminable", "two_link"),
                "discriminable_wrong": c["discriminable"] - c["discriminable_right"],
                "discriminable_right_share": share("discriminable_right", "discriminable"),
                "rigid_share": share("rigid", "two_link"),
                "jointed_right_share": ((c["right"] - c["rigid_right"]) / (c["two_link"] - c["rigid"])
                                        if c["two_link"] > c["rigid"] else math.nan),
                "ambiguous_without_share": share("ambiguous_without", "two_link")}


def run(json_path: Path | None = None, cases: int = 400, seed: int = 0, scenes: list[str] | None = None,
        reality: str = "typical") -> dict:

    results = {name: evaluate(name, cases, seed, reality=reality) for name in scenes or SCENES}
    table = Table(title=f"link isolation by motor currents, force line crossing two links ({cases} sampled contacts "
                        f"per scene, reality {reality}, no identification)")
    for col in ("scene", "two-link cases", "without currents: flagged", "unflagged wrong", "right with currents",
                "flagged", "silently wrong", "rigid (no joint between)", "right where a joint separates",
                "discriminable (>4 sigma)", "right among discriminable"):
        table.add_column(col, justify="left" if col == "scene" else "right")
    for name, r in results.items():
        unflagged_wrong = r["two_link"] - r["ambiguous_without"] - r["right_without"]
        table.add_row(name, str(r["two_link"]), f"{r['ambiguous_without_share']:.1%}", str(unflagged_wrong),
                      f"{r['right_share']:.1%}",
                      f"{r['flagged'] / max(1, r['two_link']):.1%}", f"{r['wrong_share']:.1%}",
                      f"{r['rigid_share']:.1%} ({r['rigid_right']} right, {r['rigid_flagged']} flagged, "
                      f"{r['rigid_wrong']} wrong)",
                      f"{r['jointed_right_share']:.1%}",
                      f"{r['discriminable_share']:.1%}", f"{r['discriminable_right_share']:.1%}")
    table_console().print(table)
    if json_path is not None:
        json_path.write_text(json.dumps(results, indent=2))
    return results
