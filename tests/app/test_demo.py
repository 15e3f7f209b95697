"""``ftc demo`` in a terminal (a pty), as a user runs it: in its default ``typical`` world the drawn arm
is identified first (a short planned excitation on the emulated devices), then the live view renders
without errors, and the run ends by itself with the summary against ground truth and exit status 0
(or 3, degraded, by the host's load alone)."""
from __future__ import annotations

import os
import pty
import re
import select
import subprocess
import sys
import time

import pytest

pytestmark = pytest.mark.realtime  # against the wall clock: ./run-tests runs it alone, after the others


def run_in_pty(args: list[str], timeout: float = 180) -> tuple[int, str]:
    master, slave = pty.openpty()
    env = {**os.environ, "TERM": "xterm-256color", "COLUMNS": "140", "LINES": "50"}
    proc = subprocess.Popen(args, stdin=slave, stdout=slave, stderr=slave, env=env, close_fds=True)
    os.close(slave)
    chunks = []
    end = time.monotonic() + timeout
    try:
        while time.monotonic() < end:
            if select.select([master], [], [], 0.5)[0]:
                try:
                    data = os.read(master, 65536)
                except OSError:  # EIO: the child closed the terminal
                    break
                if not data:
                    break
                chunks.append(data)
            elif proc.poll() is not None:
                break
        rc = proc.wait(timeout=max(1.0, end - time.monotonic()))
    finally:
        if proc.poll() is None:
            proc.kill()
        os.close(master)
    return rc, b"".join(chunks).decode("utf-8", errors="replace")


def test_demo_renders_live_in_a_terminal_and_ends_with_the_summary(clean_or_loaded):
    rc, out = run_in_pty([sys.executable, "-m", "ftc_hw", "demo", "--duration", "10", "--identify-seconds", "15"])
    loaded = clean_or_loaded(rc, re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", out))
    assert "Traceback" not in out and "Error" not in out, out[-4000:]
    assert "\x1b[" in out  # a terminal: rich drew (and redrew) the live view with escape sequences
    plain = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", out)
    assert plain.count("ftc demo") >= 3  # the live view was refreshed, not printed once
    for part in ("wrench (sensor frame)", "contact (base frame)", "CONTACT", "fused", "wrist_3", "monitor/input",
                 "contacts: detected against ground truth"):
        assert part in plain, part
    # ends by itself with the summary: the 10 s run's two collisions, found (tests/cli once ran it again
    # through typer's runner only for this). Two: a model identified from 15 s keeps a large error while
    # the arm moves, and once held the first contact open to the run's end, hiding the second
    said = " ".join(plain.split())
    assert "reality typical" in said and "step 1/2: identifying the drawn arm" in said, said[:3000]
    assert "contact points on the scene's meshes" in said, said[:3000]  # UR's, fetched by the bootstrap
    assert "summary: a typical draw of another arm" in said, said[-3000:]
    # identified, then monitored with it; only a host that fell behind while recording the excitation
    # (that run says DEGRADED) may leave too little joint state to identify from: the demo then says so
    # and monitors with the nominal model
    identifying = said.split("step 1/2", 1)[1].split("ftc demo scene ur5e", 1)[0]
    # the excitation has no contact: the model not yet identified raises alarms there, said as not judged
    assert "contacts not judged: a recording of free motion" in identifying and "true contacts" not in identifying
    assert ("step 2/2: the monitor with that calibration" in said and "identified first" in said) or (
        "DEGRADED run" in identifying and "its identification failed" in said), said[-6000:]
    # the collision found; only a run that said its host left F/T frames unjudged (exit 3: "contacts may
    # be missed") may miss it
    judged_all = not any("of F/T frames not judged" in r for r in loaded)
    found = re.search(r"(\d)/2 contacts detected, \d+ within 3 ms of their first sample, \d+ false alarms", said)
    assert found and (found.group(1) == "2" or not judged_all), said[-3000:]
