"""The layers of docs/architecture.md hold, and each contract that says so can fail.

``lint-imports`` checks the import-linter contracts in pyproject.toml. Each case below copies the
package, adds one import that a contract forbids, and expects that contract to break: a contract
that nothing can break would check nothing.
"""
from __future__ import annotations

import ast
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LINT = Path(sys.executable).parent / "lint-imports"
LAYERS = "Layers: each imports only from the layers below it"
EMULATORS = "Emulators see the world only through the link"
NAMESPACE = "Namespace: devices, calibration, sim_devices only as ftc_hw.<folder>"
APP = "App: its packages import only from those below them"
ROS = "ROS: rclpy, ROS messages and rosbags only in ftc_hw.app.ros"


def _lint(root: Path) -> subprocess.CompletedProcess:
    return subprocess.run([str(LINT), "--no-cache"], cwd=root, capture_output=True, text=True, timeout=120,
                          env={"PYTHONPATH": str(root), "PATH": "/usr/bin:/bin"})


FOLDERS = ("devices", "calibration", "sim_devices")  # installed as ftc_hw.<folder> (symlinks in ftc_hw/)


def _product_files() -> list[Path]:
    """Every module of the product, each once (the folders by their real paths, not through the links)."""
    files = [p for p in (ROOT / "ftc_hw").rglob("*.py") if not any(part in FOLDERS for part in p.parts[-3:-1])]
    files += [p for d in FOLDERS for p in (ROOT / d).rglob("*.py")]
    return sorted(p for p in files if "__pycache__" not in p.parts)


@pytest.fixture(scope="module")
def pristine(tmp_path_factory) -> Path:
    """A copy of the checkout's package (symlinks followed), its folders and pyproject.toml."""
    root = tmp_path_factory.mktemp("pristine")
    skip = shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc")
    shutil.copytree(ROOT / "ftc_hw", root / "ftc_hw", symlinks=False, ignore=skip)
    for folder in FOLDERS:  # importable by their own names from a checkout: what the namespace contract forbids
        shutil.copytree(ROOT / folder, root / folder, ignore=skip)
    shutil.copy(ROOT / "pyproject.toml", root)
    return root


def test_the_code_keeps_every_contract():
    r = _lint(ROOT)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "0 broken" in r.stdout


CASES = [  # (module, an import it must not make, the contract that forbids it)
    ("ftc_hw/bench/report.py", "import ftc_hw.cli", LAYERS),
    ("ftc_hw/app/monitor/view.py", "import ftc_hw.bench.report", LAYERS),
    ("ftc_hw/devices/base.py", "import ftc_hw.app.setup.rig", LAYERS),
    ("ftc_hw/devices/base.py", "import ftc_hw.sim_devices.link", LAYERS),  # siblings, independent
    ("ftc_hw/sim_devices/link.py", "import ftc_hw.devices.base", LAYERS),
    ("ftc_hw/calibration/file.py", "import ftc_hw.devices.base", LAYERS),
    ("ftc_hw/calibration/file.py", "import ftc_hw.record.events", LAYERS),
    ("ftc_hw/record/events.py", "import ftc_hw.app.monitor.view", LAYERS),
    ("ftc_hw/monitor.py", "import ftc_hw.record.writer", LAYERS),
    ("ftc_hw/pipeline/contact.py", "import ftc_hw.monitor", LAYERS),
    ("ftc_hw/pipeline/settings.py", "import ftc_hw.calibration.file", LAYERS),
    ("ftc_hw/tracking.py", "import ftc_hw.pipeline", LAYERS),
    ("ftc_hw/solver/solver.py", "import ftc_hw.tracking", LAYERS),
    ("ftc_hw/solver/solver.py", "import ftc_hw.compensation", LAYERS),
    ("ftc_hw/model/arm.py", "import ftc_hw.solver", LAYERS),
    ("ftc_hw/bus/bus.py", "import ftc_hw.model", LAYERS),
    ("ftc_hw/codecs/errors.py", "import ftc_hw.bus", LAYERS),
    ("ftc_hw/scene/errors.py", "import ftc_hw.priority", LAYERS),
    ("ftc_hw/sim_devices/ft300.py", "import ftc_hw.sim_devices.world", EMULATORS),
    ("ftc_hw/bus/frames.py", "import devices.base", NAMESPACE),
    ("ftc_hw/app/calibration/identify.py", "import ftc_hw.app.demo", APP),
    ("ftc_hw/app/monitor/session.py", "import ftc_hw.app.calibration.identify", APP),
    ("ftc_hw/app/web/page.py", "import ftc_hw.app.calibration.identify", APP),
    ("ftc_hw/app/web/feed.py", "import ftc_hw.app.monitor.view", APP),
    ("ftc_hw/app/web/feed.py", "import ftc_hw.app.serving.serve", APP),  # siblings, independent
    ("ftc_hw/app/serving/serve.py", "import ftc_hw.app.web.feed", APP),
    ("ftc_hw/app/setup/rig.py", "import ftc_hw.app.serving.remote_rig", APP),
    ("ftc_hw/app/ros/availability.py", "import ftc_hw.app.web.feed", APP),  # siblings, independent
    ("ftc_hw/app/web/feed.py", "import ftc_hw.app.ros.availability", APP),
    ("ftc_hw/app/monitor/session.py", "import rclpy", ROS),
    ("ftc_hw/record/writer.py", "import rosbags.rosbag2", ROS),
    ("ftc_hw/devices/base.py", "from sensor_msgs.msg import JointState", ROS),
]


@pytest.mark.parametrize(("module", "line", "contract"), CASES, ids=[f"{m}:{line}" for m, line, _ in CASES])
def test_a_forbidden_import_breaks_its_contract(pristine, tmp_path, module, line, contract):
    root = tmp_path / "tree"
    shutil.copytree(pristine, root)
    assert (root / module).is_file(), f"{module}: no such module (moved?)"
    with open(root / module, "a", encoding="utf-8") as f:
        f.write(f"\n{line}  # the forbidden import\n")
    r = _lint(root)
    assert r.returncode == 1, r.stdout
    broken = r.stdout.split("Broken contracts", 1)[-1]
    source = module.removesuffix(".py").replace("/", ".")
    assert contract in broken and f"{source} -> " in broken, r.stdout


@pytest.mark.parametrize("parent", ["ftc_hw", "ftc_hw.app"])
def test_a_new_package_must_be_given_a_layer(pristine, tmp_path, parent):
    root = tmp_path / "tree"
    shutil.copytree(pristine, root)
    package = root.joinpath(*parent.split("."), "newcomer")
    package.mkdir()
    (package / "__init__.py").write_text('"""Not in any layer yet."""\n')
    r = _lint(root)
    assert r.returncode == 1 and f"{parent}.newcomer" in r.stdout, r.stdout


def _function_local_imports(path: Path) -> list[tuple[int, str]]:
    lines = path.read_text(encoding="utf-8").splitlines()
    tree = ast.parse("\n".join(lines))
    functions = [fn for fn in ast.walk(tree) if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef))]
    return sorted({(n.lineno, lines[n.lineno - 1]) for fn in functions for n in ast.walk(fn)
                   if isinstance(n, (ast.Import, ast.ImportFrom))})


def test_function_local_imports_are_lazy_on_purpose_and_say_why():
    unexplained = [f"{p.relative_to(ROOT)}:{n}: {text.strip()}" for p in _product_files()
                   for n, text in _function_local_imports(p) if "# lazy:" not in text]
    assert not unexplained, "imports inside functions without a '# lazy: <why>' comment:\n" + "\n".join(unexplained)


def test_the_sensor_sign_convention_is_decoded_in_one_place():
    """``[sensor] reports`` is turned into a sign by ``SensorSpec.reading_sign`` only; everything else
    (model, solver, world, calibration) takes that sign."""
    places = []
    for p in _product_files():
        for node in ast.walk(ast.parse(p.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Constant) and node.value in ("base_on_arm", "arm_on_base"):
                places.append(p.relative_to(ROOT).as_posix())
    assert set(places) == {"ftc_hw/scene/schema.py"}, places
