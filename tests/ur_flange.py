"""A test variant of ur5e whose F/T sensor is a UR e-Series' built-in flange sensor, read through the
arm's own RTDE connection: no F/T device of its own (tests of the UR emulator and adapter)."""
from __future__ import annotations

from pathlib import Path

from ftc_hw.scene import Scene, load_scene
from ftc_hw.scene.loader import builtin_dir

# Tables merge key by key over ur5e.toml's; [[devices]] replaces its list (the ft-can device goes).
VARIANT = """schema = 1
extends = "ur5e"
name = "ur5e-flange-test"
description = "UR5e with its built-in flange F/T sensor read over RTDE (test variant)"

[robot]
model = "{model}"

[sensor]
site = "flange"                         # the tool flange frame: the sensor's
mount = "flange"
reports = "{reports}"
# UR-like: the order of an e-Series' flange sensor (100 N, 10 N m; the issue's test brief); ESTIMATE
range = [100.0, 100.0, 100.0, 10.0, 10.0, 10.0]
noise_std = [1.0, 1.0, 1.0, 0.05, 0.05, 0.05]    # ESTIMATE: the order of a few per cent of range
quantization = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
rate_hz = 500.0                         # sampled in the controller's 500 Hz cycle (RTDE's maximum)
# the sensor carries nothing on a bare flange (it sits between wrist 3 and the tool): its bias is what it
# reads, and makes the reading tell itself from zeros
bias = [1.5, -0.8, 2.0, 0.06, -0.04, 0.02]
drift_per_s = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]

[[devices]]
name = "arm"
kind = "ur-rtde"
transport = "tcp"
[devices.params]
frequency = 500.0
controller_version = "5.9"
"""


def flange_scene(directory: Path, reports: str = "arm_on_base") -> Scene:
    """ur5e with a flange sensor at its ``flange`` site, written to ``directory`` and loaded."""
    path = Path(directory) / "ur5e-flange-test.toml"
    path.write_text(VARIANT.format(model=(builtin_dir() / "ur5e.xml").as_posix(), reports=reports))
    return load_scene(path)
