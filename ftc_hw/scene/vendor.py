"""Vendors' meshes of a robot's shell, as data: where a package on the index ships them, which of the
vendor model's bodies is which of ours, and where ``ftc scenes meshes`` puts them on this machine.

The simulated world uses them as the true touched surface (``[world] vendor_shell``, or the scene's
``[robot] vendor_shell``), and the pipeline answers on them (``ftc_hw.model.mesh_surface``).
Nothing here downloads: ``ftc_hw.app.setup.vendor_meshes`` does.
"""
from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class VendorShell:
    name: str
    requirement: str  # pip requirement of the package that ships the meshes
    root: str  # the robot's folder inside the package's wheel
    model: str  # the vendor's MuJoCo model, relative to ``root``: its kinematics place the meshes
    licence: str  # the package's licence, and the file of it that is copied along
    licence_file: str  # path inside the wheel
    bodies: Mapping[str, str]  # our body -> the vendor model's body, whose visual meshes are the shell
    base_yaw: float  # rad: the vendor's base frame is ours turned by this about z (same joint zeros)
    tolerance_m: float  # 1 sigma per axis: how far a real arm's shell lies from these meshes


def _robosuite(robot: str, maker: str, bodies: Mapping[str, str], base_yaw: float) -> VendorShell:
    """A robot of robosuite 1.5.2's assets: its ``robot.xml`` and visual meshes (what a hand touches;
    the collision meshes are coarser hulls)."""
    return VendorShell(
        name=f"robosuite-{robot}", requirement="robosuite==1.5.2", root=f"robosuite/models/assets/robots/{robot}",
        model="robot.xml", licence=f"MIT (robosuite 1.5.2; the meshes are {maker} meshes)",
        licence_file="robosuite-1.5.2.dist-info/licenses/LICENSE", bodies=bodies, base_yaw=base_yaw,
        # ESTIMATE: cast and machined aluminium housings (and covers) against their CAD, about +-1 mm
        # (ISO 8062 CT8-CT9 at 100-250 mm), uniform: 1 mm / sqrt(3)
        tolerance_m=0.001 / math.sqrt(3.0))


VENDOR_SHELLS: dict[str, VendorShell] = {
    # UR's collision meshes are up to 40 mm outside the upper arm's tube.
    # base_yaw: ROS-style base_link vs the DH base: joint anchors agree to 0.5 mm turned by pi
    "robosuite-ur5e": _robosuite(
        "ur5e", "Universal Robots' UR5e",
        {"base": "fixed_base_link", "shoulder": "shoulder_link", "upper_arm": "upper_arm_link",
         "forearm": "forearm_link", "wrist_1": "wrist_1_link", "wrist_2": "wrist_2_link", "wrist_3": "wrist_3_link"},
        base_yaw=math.pi),
    # base_yaw: its link frames are Franka's modified-DH frames, as ours (they agree to 1e-14 m at any q)
    "robosuite-panda": _robosuite("panda", "Franka Emika's Panda", {f"link{i}": f"link{i}" for i in range(8)},
                                  base_yaw=0.0),
}


def vendor_root() -> Path:
    """Where fetched vendor meshes live: ``$FTC_VENDOR_DIR``, else ``~/.cache/ftc-hw/vendor``."""
    env = os.environ.get("FTC_VENDOR_DIR")
    return Path(env) if env else Path.home() / ".cache" / "ftc-hw" / "vendor"


def shell_model(name: str) -> Path:
    """The fetched vendor model file of shell ``name`` (it may not exist: :func:`shell_fetched`)."""
    shell = VENDOR_SHELLS[name]
    return vendor_root() / name / shell.model


def shell_fetched(name: str) -> bool:
    return name in VENDOR_SHELLS and shell_model(name).is_file()
