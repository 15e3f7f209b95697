"""Every test in the folders where most tests run against the wall clock says whether it does.

``./run-tests`` runs the tests marked ``realtime`` one at a time, after the others (which share every
core): a real-time test left unmarked would run beside computing tests and flake under their load.
So in these folders each test is marked ``realtime`` or ``compute``, exactly one of them, on its
module (``pytestmark``) or on itself (tests/conftest.py says the rule). Read from the sources (no
import), so this costs nothing.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

pytestmark = pytest.mark.compute  # reads the test sources

TESTS = Path(__file__).resolve().parent
REALTIME_HEAVY = ("app", "devices", "sim", "cli", "record")
DECISIONS = {"realtime", "compute"}


def _marks(node: ast.expr | None) -> set[str]:
    """The marker names ``pytest.mark.<name>`` written in ``node`` (a decorator, a list of them)."""
    if node is None:
        return set()
    out = set()
    for sub in ast.walk(node):
        if (isinstance(sub, ast.Attribute) and isinstance(sub.value, ast.Attribute) and sub.value.attr == "mark"
                and isinstance(sub.value.value, ast.Name) and sub.value.value.id == "pytest"):
            out.add(sub.attr)
    return out & DECISIONS


def _undecided(path: Path, root: Path = TESTS.parent) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    module = set()
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "pytestmark" for t in node.targets):
            module |= _marks(node.value)
    tests: list[tuple[str, set[str]]] = []
    for node in tree.body:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and node.name.startswith("test"):
            tests.append((node.name, set().union(*(_marks(d) for d in node.decorator_list))))
        elif isinstance(node, ast.ClassDef) and node.name.startswith("Test"):
            own = set().union(*(_marks(d) for d in node.decorator_list))
            for item in node.body:
                if isinstance(item, ast.FunctionDef | ast.AsyncFunctionDef) and item.name.startswith("test"):
                    tests.append((f"{node.name}.{item.name}",
                                  own | set().union(*(_marks(d) for d in item.decorator_list))))
    bad = []
    for name, marks in tests:
        decided = module | marks
        if len(decided) != 1:
            bad.append(f"{path.relative_to(root)}::{name}: " +
                       ("neither realtime nor compute" if not decided else "both realtime and compute"))
    return bad


def test_every_test_in_the_real_time_folders_is_marked_realtime_or_compute():
    files = sorted(p for d in REALTIME_HEAVY for p in (TESTS / d).glob("test_*.py"))
    assert len(files) > 40  # the folders are where they were
    bad = [line for p in files for line in _undecided(p)]
    assert not bad, "mark these realtime or compute (tests/conftest.py):\n" + "\n".join(bad)


def test_the_guard_sees_a_test_that_says_neither(tmp_path):
    (tmp_path / "test_x.py").write_text("import pytest\n\n\n@pytest.mark.realtime\ndef test_a():\n    pass\n\n\n"
                                        "def test_b():\n    pass\n\n\nclass TestC:\n    @pytest.mark.compute\n"
                                        "    def test_d(self):\n        pass\n")
    found = _undecided(tmp_path / "test_x.py", tmp_path)
    assert [line.split("::")[1] for line in found] == ["test_b: neither realtime nor compute"]
