"""Fixtures that several layers' tests use: sampled contacts (core, app), small custom scenes
(core, model) and what a monitor run's exit code may say (app, record). Each layer's own fixtures
are in its folder's ``conftest.py``.

Real-time tests are marked where they are defined. A test whose world, emulators or streams run
against the wall clock is marked ``realtime`` (``pytestmark = pytest.mark.realtime`` at a module's
top, or ``@pytest.mark.realtime`` on the test): ``./run-tests`` runs those one at a time, and the
others beside them on every core at the lowest priority (``-m "not realtime"`` with pytest-xdist). A test that uses the
``world_feeder`` fixture is real-time without saying so (the hook below). In the folders where most
tests are real-time (``app``, ``devices``, ``sim``, ``cli``, ``record``) every test says which it is:
``realtime``, or ``compute`` (it only computes: worlds stepped as fast as they go, files, codecs,
refusals); ``tests/test_markers.py`` fails on a test there that says neither. ``./run-tests`` runs the
computing tests beside the real-time ones at the lowest priority, so a computing test's wall time says nothing:
Hypothesis runs without its per-example deadline (speed is measured by ``ftc bench``)."""
from __future__ import annotations

import gc
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings as hypothesis_settings

from ftc_hw.model import ArmModel
from ftc_hw.pipeline import SECTION_TYPES, PipelineSettings
from ftc_hw.scene import Scene, load_scene
from ftc_hw.sim_devices.world.scenarios import sample_contacts

hypothesis_settings.register_profile("ftc", deadline=None)
hypothesis_settings.load_profile("ftc")


def settings(**values) -> PipelineSettings:
    """Tests' shorthand: ``PipelineSettings`` from field names (``level="gravity", use_currents=False``),
    each put in the section that has it."""
    owner = {f: name for name, cls in SECTION_TYPES.items() for f in cls.__dataclass_fields__}
    sections: dict[str, dict] = {name: {} for name in SECTION_TYPES}
    for k, v in values.items():
        sections[owner[k]][k] = v
    return PipelineSettings(**{name: SECTION_TYPES[name](**kw) for name, kw in sections.items()})


# Real-time tests run last from these folders: ``./run-tests`` starts the computing leg beside the real-time
# one, and its first minutes (workers importing, numba compiling) are the host's busiest. A ROS node's
# executor is Python on the monitor's own core; run first, the ROS cell's monitor fell 50 ms behind its
# 1 kHz topic for seconds (CI, stop 44). Last, they run after the computing leg has ended.
RUN_LAST = ("tests/app/ros/",)


def pytest_collection_modifyitems(config, items):
    for item in items:
        # a test fed by a real-time world is real-time wherever it is (tests/core/conftest.py's fixture)
        if "world_feeder" in getattr(item, "fixturenames", ()) and not item.get_closest_marker("realtime"):
            item.add_marker(pytest.mark.realtime)
    items.sort(key=lambda item: bool(item.get_closest_marker("realtime")) and item.nodeid.startswith(RUN_LAST))


@pytest.fixture(autouse=True)
def _no_collector_pause(request):
    """Before a real-time test, the test process's heap is collected and frozen (``gc.freeze``, as the monitor
    freezes its own: ``ftc_hw.devices.base.frozen_heap``): the adapters and clients a test runs in this process
    are otherwise stalled by full collections that walk every object the session has loaded, 70-116 ms here
    (a Modbus request then timed out at its 0.1 s). Only what earlier tests left is walked: milliseconds."""
    if request.node.get_closest_marker("realtime") is not None:
        gc.collect()
        gc.freeze()
    yield


SCENE = """schema = 1
name = "{name}"
[robot]
model = "{name}.xml"
joints = ["j1", "j2"]
home = [0.3, -0.4]
[gravity]
vector = [0.0, 0.0, -9.81]
[sensor]
site = "ft"
reports = "{reports}"
range = [1000.0, 1000.0, 1000.0, 100.0, 100.0, 100.0]
noise_std = [0.1, 0.1, 0.1, 0.005, 0.005, 0.005]
rate_hz = 1000.0
[[touchable]]
link = "l1"
[[touchable]]
link = "l2"
[compensation]
level = "gravity"
"""

MJCF = """<mujoco>
  <worldbody>
    <body name="base" pos="{offset}">
      <site name="ft"/>
      <inertial pos="0 0 0" mass="1" diaginertia="0.01 0.01 0.01"/>
      <body name="l1" pos="0 0 0.1">
        <joint name="j1" axis="0 0 1"/>
        <inertial pos="0 0 0.1" mass="1" diaginertia="0.01 0.01 0.01"/>
        <geom type="{kind1}" size="{size1}" pos="0 0 0.2" group="1"/>
        <body name="l2" pos="0 0 0.5">
          <joint name="j2" axis="0 1 0"/>
          <inertial pos="0.1 0 0" mass="1" diaginertia="0.01 0.01 0.01"/>
          <geom type="{kind2}" size="{size2}" pos="{pos2}" euler="0 1.5707963267948966 0" group="1"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def _contacts(model: ArmModel, q, n: int, seed: int, max_angle_deg: float = 80.0, f_range=(5.0, 200.0)):
    """(surface point, force applied to the arm) pairs: uniform on the touchable surfaces, pushing in."""
    return sample_contacts(model, q, n, np.random.default_rng(seed), max_angle_deg, f_range)


def _custom_scene(tmp: Path, name: str, kind1: str, size1: str, kind2: str, size2: str, pos2: str = "0.3 0 0",
                  offset: str = "0 0 0", reports: str = "base_on_arm") -> Scene:
    """A two-link arm (geoms ``kind1``/``kind2`` of MuJoCo sizes ``size1``/``size2``) written to ``tmp``."""
    (tmp / f"{name}.xml").write_text(MJCF.format(kind1=kind1, size1=size1, kind2=kind2, size2=size2, pos2=pos2,
                                                 offset=offset))
    path = tmp / f"{name}.toml"
    path.write_text(SCENE.format(name=name, reports=reports))
    return load_scene(path)


@pytest.fixture(scope="session")
def contacts():
    """``contacts(model, q, n, seed)``: n seeded (surface point, force) pairs pushing into the touchable surfaces."""
    return _contacts


@pytest.fixture(scope="session")
def custom_scene():
    """``custom_scene(tmp, name, kind1, size1, kind2, size2)``: a two-link scene with those geoms, written to tmp."""
    return _custom_scene

# reasons a run on a loaded host may give that say nothing against the code under test (the world
# process or the monitor fell behind real time); a lost stream or a dropped device is never one
# (with emulators, frames late by their device clock are the world running behind real time)
LOAD_REASONS = ("of F/T frames not judged", "the host could not keep up", "the F/T frames came late")


def _clean_or_loaded(rc: int, text: str) -> list[str]:
    """A monitor run must be clean (exit 0), or degraded (exit 3) by its host's load alone; returns
    the load reasons it gave (reported by the caller, never silently passed)."""
    # the last session's own output (ftc demo's identification first runs a session of its own)
    flat = " ".join(text.split()).rsplit("starting the world (MuJoCo", 1)[-1]
    if rc == 0:
        assert "DEGRADED run" not in flat, flat[-3000:]
        return []
    assert rc == 3 and "DEGRADED run (exit code 3): " in flat, f"exit code {rc}: {flat[-3000:]}"
    # the session's last line (ftc demo prints its own summary after it)
    reasons = flat.split("DEGRADED run (exit code 3): ", 1)[1].split(" summary: ", 1)[0].split("; ")
    other = [r for r in reasons if not any(k in r for k in LOAD_REASONS)]
    assert not other, f"degraded for a reason other than load: {other}"
    return reasons


@pytest.fixture(scope="session")
def clean_or_loaded():
    """``clean_or_loaded(returncode, output)``: exit 0, or exit 3 with load reasons only (returned)."""
    return _clean_or_loaded
