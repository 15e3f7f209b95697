"""The code blocks of README.md and of the guides in docs/, run or checked as a reader would use them.

- ``python`` blocks run, each page's in order in one fresh namespace (a page's blocks may build on each
  other), in a subprocess of their own with a scratch folder as the working directory. A block that needs
  what this host has not (devices, a rig, a recording, a running world: the values it names come from
  there) is preceded by ``<!-- not run: why -->``: it is compiled, and every name it imports is imported
  and looked up, but it is not run.
- ``bash`` blocks: every ``ftc ...`` line (and ``./ftc``, ``.venv/bin/ftc``) is checked against the CLI:
  the command and subcommand exist, and every option the line gives is one that command has. Option
  synopses (``[--seed N]``, ``terminal|web``, ``...``) are read the same way. Quick commands (``--help``,
  ``--version``, ``ftc scenes``, ``ftc sim --list``) are run. Of the other lines, ``./ftc``,
  ``./run-tests`` and ``scripts/...`` must exist; ``python -m MODULE`` must name a module that imports.
  Lines that need devices, a world or minutes are parsed and checked, not run.
- ``toml`` and ``json`` blocks parse (a ``...`` line stands for the rest and is left out).

It only computes (nothing against the wall clock): it runs with the compute group (tests/conftest.py).
"""
from __future__ import annotations

import importlib
import json
import re
import shlex
import subprocess
import sys
import textwrap
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

from ftc_hw.cli import app

pytestmark = pytest.mark.compute

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted([ROOT / "README.md", *(ROOT / "docs").glob("*.md"), *(ROOT / "docs" / "measurements").glob("*.md")])
FENCE = re.compile(r"^```(\w*)[^\n]*\n(.*?)^```\s*$", re.S | re.M)
NOT_RUN = re.compile(r"<!--\s*not run:\s*(.+?)\s*-->\s*$", re.S)
FTC = {"ftc", "./ftc", ".venv/bin/ftc"}
QUICK = [("--help",), ("--version",), ("scenes",), ("sim", "--list")]  # a line of only these is run


@dataclass
class Block:
    page: Path
    line: int
    lang: str
    code: str
    not_run: str | None  # why it is not run, or None

    def __str__(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"


def blocks(page: Path, lang: str | None = None) -> list[Block]:
    text = page.read_text()
    found = []
    for m in FENCE.finditer(text):
        before = text[:m.start()].rstrip()
        why = NOT_RUN.search(before[-300:])
        found.append(Block(page, text.count("\n", 0, m.start()) + 1, m.group(1), m.group(2),
                           why.group(1) if why else None))
    return [b for b in found if lang is None or b.lang == lang]


def _pages_with(lang: str) -> list[Path]:
    return [p for p in PAGES if blocks(p, lang)]


def _rel(page: Path) -> str:
    return str(page.relative_to(ROOT))


# ---- python ----------------------------------------------------------------------------------------

RUNNER = textwrap.dedent("""
    import json, sys, traceback
    blocks = json.load(sys.stdin)
    namespace = {"__name__": "__docs__"}
    for where, code in blocks:
        try:
            exec(compile(code, where, "exec"), namespace)
        except BaseException:
            traceback.print_exc()
            print(f"FAILED in the block at {where}", file=sys.stderr)
            sys.exit(1)
""")


def _imports(block: Block) -> list[str]:
    """Every name the block imports, imported and looked up: the problems, one line each."""
    import ast

    problems = []
    for node in ast.walk(ast.parse(block.code, str(block))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                try:
                    importlib.import_module(alias.name)
                except ImportError as e:
                    problems.append(f"{block}: import {alias.name}: {e}")
        elif isinstance(node, ast.ImportFrom) and node.module:
            try:
                module = importlib.import_module(node.module)
            except ImportError as e:
                problems.append(f"{block}: from {node.module}: {e}")
                continue
            for alias in node.names:
                if not hasattr(module, alias.name):
                    try:
                        importlib.import_module(f"{node.module}.{alias.name}")
                    except ImportError:
                        problems.append(f"{block}: {node.module} has no {alias.name}")
    return problems


@pytest.mark.parametrize("page", _pages_with("python"), ids=_rel)
def test_python_blocks_run(page, tmp_path):
    code = blocks(page, "python")
    problems = []
    for block in code:
        try:
            compile(block.code, str(block), "exec")
        except SyntaxError as e:
            problems.append(f"{block}: {e}")
            continue
        if block.not_run:
            problems += _imports(block)
    assert not problems, "\n".join(problems)
    runnable = [(str(b), b.code) for b in code if not b.not_run]
    if not runnable:
        return
    out = subprocess.run([sys.executable, "-c", RUNNER], input=json.dumps(runnable), capture_output=True,
                         text=True, cwd=tmp_path, timeout=240)
    assert out.returncode == 0, out.stderr[-4000:]


# ---- shell -----------------------------------------------------------------------------------------

ROOT_COMMAND = typer.main.get_command(app)


def _lines(code: str) -> list[str]:
    """The block's command lines: continuations joined, comments and prompts left out."""
    joined = re.sub(r"\\\n\s*", " ", code)
    out = []
    for line in joined.splitlines():
        line = line.strip()
        if line.startswith("$ "):
            line = line[2:]
        try:
            words = shlex.split(line, comments=True)
        except ValueError:  # an unbalanced quote in a synopsis
            words = line.split("#", 1)[0].split()
        if words:
            out.append(words)
    return out


def _option_names(command) -> set[str]:
    names = {"--help"}
    for param in command.params:
        names.update(getattr(param, "opts", ()))
        names.update(getattr(param, "secondary_opts", ()))
    return names


def check_ftc(words: list[str]) -> tuple[list[str], list[str]]:
    """The command path of an ``ftc`` line and what is wrong with it (empty when nothing is)."""
    synopsis = any(c in w for w in words for c in "[]|") or "..." in words  # [--seed N], a|b, ...
    words = [w for w in (w.strip("[]") for w in words[1:]) if w and w != "..."]
    for i, w in enumerate(words):
        if w in {"|", ">", "<", "&", "&&", ";"} or w.startswith((">", "<")):
            words = words[:i]
            break
    command, path = ROOT_COMMAND, ["ftc"]
    while hasattr(command, "list_commands") and words and not words[0].startswith("-"):
        sub = command.get_command(None, words[0])
        if sub is None:
            return path, [f"no command {' '.join([*path, words[0]])!r}"]
        command, path, words = sub, [*path, words[0]], words[1:]
    problems = []
    if hasattr(command, "list_commands") and "--help" not in words and path != ["ftc"]:
        problems.append(f"{' '.join(path)!r} needs a subcommand")
    known = _option_names(command)
    for w in words:
        for alt in w.split("|"):  # a synopsis' alternatives: --fast|--realtime
            alt = alt.strip("[]")
            if alt.startswith("-") and not re.fullmatch(r"-?\d[\d.e-]*", alt):
                name = alt.split("=", 1)[0]
                if name not in known:
                    problems.append(f"{' '.join(path)} has no option {name}")
    if not problems and not synopsis and "--help" not in words:
        problems += _parse(command, path, words)  # a whole command line: parsed as ftc would
    return path, problems


def _parse(command, path: list[str], words: list[str]) -> list[str]:
    """What click says of the line: values of the wrong type or choice, a missing or extra argument. A file
    the command wants to exist (a calibration, a Zenoh configuration) is the reader's, not the page's."""
    try:
        command.make_context(path[-1], list(words))
    except Exception as e:  # click's usage errors, of whichever click typer vendors
        message = e.format_message() if hasattr(e, "format_message") else str(e)
        if re.search(r"(file|directory|path) '[^']*' does not exist", message, re.I):
            return []
        return [f"{' '.join(path)}: {message}"]
    return []


def _shell_blocks() -> list[Block]:
    return [b for p in PAGES for b in blocks(p) if b.lang in {"bash", "sh", "shell", "console"}]


@pytest.mark.parametrize("block", _shell_blocks(), ids=str)
def test_shell_blocks_name_real_commands_and_options(block):
    problems = []
    for words in _lines(block.code):
        head = words[0]
        if head in FTC:
            _, wrong = check_ftc(words)
            problems += [f"{block}: {' '.join(words)}: {w}" for w in wrong]
        elif head.startswith(("./", "scripts/")):
            if not (ROOT / head).exists():
                problems.append(f"{block}: {head}: no such file in the checkout")
        elif head.endswith("python") and words[1:2] == ["-m"]:
            try:
                importlib.import_module(words[2])
            except ImportError as e:
                problems.append(f"{block}: python -m {words[2]}: {e}")
    assert not problems, "\n".join(problems)


def _quick_lines() -> list[tuple[str, tuple[str, ...]]]:
    """The quick lines the pages give, and ``--help`` of every command they name."""
    found: dict[tuple[str, ...], str] = {}
    for block in _shell_blocks():
        for words in _lines(block.code):
            if words[0] not in FTC:
                continue
            if tuple(words[1:]) in QUICK or words[-1] == "--help":
                found.setdefault(tuple(words[1:]), str(block))
            path, wrong = check_ftc(words)
            if not wrong:
                found.setdefault((*path[1:], "--help"), str(block))
    return [(where, args) for args, where in sorted(found.items())]


runner = CliRunner()


@pytest.mark.parametrize(("where", "args"), [*_quick_lines(), ("always", ("--help",)), ("always", ("sim", "--list"))],
                         ids=lambda x: " ".join(x) if isinstance(x, tuple) else x)
def test_quick_commands_run(where, args):
    result = runner.invoke(app, list(args))
    assert result.exit_code == 0, f"{where}: ftc {' '.join(args)}: {result.output}"
    assert result.output.strip()


# ---- data ------------------------------------------------------------------------------------------

def _data_blocks() -> list[Block]:
    return [b for p in PAGES for b in blocks(p) if b.lang in {"toml", "json"}]


@pytest.mark.parametrize("block", _data_blocks(), ids=str)
def test_data_blocks_parse(block):
    text = "\n".join(line for line in block.code.splitlines() if line.strip() not in {"...", "# ..."})
    text = re.sub(r",\s*\.\.\.\s*\]", "]", text)  # [a, b, ...]: the rest left out
    if block.lang == "toml":
        tomllib.loads(text)
    else:
        json.loads(text)


# ---- the checker itself ----------------------------------------------------------------------------

@pytest.mark.parametrize(("line", "wrong"), [
    ("ftc monitor --scene ur5e --sim --duration 8", []),
    ("./ftc demo --scene dxl-arm [--view terminal|web]", []),
    ("ftc bench pipeline [--scene S ...] [--rate HZ]", []),
    ("ftc monitor --scene ur5e --no-such-option 3", ["ftc monitor has no option --no-such-option"]),
    ("ftc bench nosuch", ["no command 'ftc bench nosuch'"]),
    ("ftc bench", ["'ftc bench' needs a subcommand"]),
    ("ftc sim ur5e --scenario hold --address arm=127.0.0.3 &", []),
    ("ftc monitor --scene ur5e --view nowhere", ["ftc monitor: Invalid value for '--view'"]),
    ("ftc monitor --scene ur5e --seed", ["ftc monitor: Option '--seed' requires an argument"]),
    ("ftc monitor --duration 3", ["ftc monitor: Missing option '--scene'"]),
    ("ftc replay a.mcap b.mcap", ["ftc replay: Got unexpected extra argument"]),
    ("ftc monitor --scene ur5e --calibration cal.toml", []),  # the file is the reader's
])
def test_the_checker_tells_a_wrong_line(line, wrong):
    """``wrong``: what each problem found says (a part of it: click's wording may change)."""
    found = check_ftc(shlex.split(line))[1]
    assert len(found) == len(wrong) and all(w in f for w, f in zip(wrong, found, strict=True)), found


# ---- links -----------------------------------------------------------------------------------------

LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")
DOC_PATH = re.compile(r"\bdocs/[\w/-]+\.(?:md|png)")


def test_links_between_the_pages_resolve():
    """Every relative link of a page, and every ``docs/...`` path a page or a source file names, exists."""
    missing = []
    for page in PAGES:
        text = page.read_text()
        for target in LINK.findall(text):
            if "://" not in target and not (page.parent / target).exists():
                missing.append(f"{_rel(page)}: ({target})")
    sources = [*PAGES, *(ROOT / "ftc_hw").rglob("*.py"), *(ROOT / "tests").rglob("*.py")]
    for source in sources:
        for path in set(DOC_PATH.findall(source.read_text())):
            if not (ROOT / path).exists():
                missing.append(f"{source.relative_to(ROOT)}: {path}")
    assert not missing, "\n".join(missing)
