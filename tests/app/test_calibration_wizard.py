"""``ftc calibrate`` as a person runs it: in a pseudo-terminal, answering its prompts with keystrokes,
against the emulated devices (world and emulators in their own processes, the payload hidden)."""
from __future__ import annotations

import fcntl
import json
import os
import re
import select
import shutil
import struct
import subprocess
import sys
import termios
import time
from pathlib import Path

import numpy as np
import pytest

from ftc_hw.calibration import load_calibration
from tests.app.test_fit_plots import CALIBRATE_PX, check_png

pytestmark = pytest.mark.realtime  # against the wall clock: ./run-tests runs it alone, after the others

ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]|\x1b\][^\x07]*\x07|\r")


def _ftc() -> list[str]:
    exe = shutil.which("ftc", path=str(Path(sys.executable).parent))
    return [exe] if exe else [sys.executable, "-m", "ftc_hw"]


class Terminal:
    """A child process on a pty: read what it prints, type keys."""

    def __init__(self, args: list[str], cwd: Path) -> None:
        self.master, slave = os.openpty()
        fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 60, 160, 0, 0))
        env = {**os.environ, "COLUMNS": "160", "LINES": "60", "TERM": "xterm-256color"}
        env.pop("NO_COLOR", None)
        self.proc = subprocess.Popen(args, stdin=slave, stdout=slave, stderr=slave, cwd=cwd, env=env,
                                     start_new_session=True)
        os.close(slave)
        self.text = ""

    def _read(self, timeout: float) -> bool:
        ready, _, _ = select.select([self.master], [], [], timeout)
        if not ready:
            return True
        try:
            data = os.read(self.master, 65536)
        except OSError:  # EIO: the child closed the terminal
            return False
        if not data:
            return False
        self.text += ANSI.sub("", data.decode(errors="replace"))
        return True

    def expect(self, pattern: str, timeout: float) -> str:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            m = re.search(pattern, self.text)
            if m:
                self.text = self.text[m.end():]
                return m.group(0)
            if not self._read(0.2) and not re.search(pattern, self.text):
                break
        raise AssertionError(f"no {pattern!r} within {timeout} s; the screen ends with:\n{self.text[-3000:]}")

    def type(self, keys: str) -> None:
        os.write(self.master, keys.encode())

    def finish(self, timeout: float) -> int:
        end = time.monotonic() + timeout
        while time.monotonic() < end and self._read(0.2):
            pass
        try:
            return self.proc.wait(timeout=max(1.0, end - time.monotonic()))
        finally:
            os.close(self.master)

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)


def test_interactive_wizard_completes_with_keystrokes(tmp_path):
    out, js = tmp_path / "cal.toml", tmp_path / "cal.json"
    term = Terminal([*_ftc(), "calibrate", "--scene", "dxl-arm", "--sim", "--poses", "5", "--sample-s", "0.5",
                     "--speed", "1.5", "--sim-payload", "mass=0.4,com=0.0,0.01,0.05", "--out", str(out),
                     "--json", str(js)], tmp_path)
    try:
        term.expect(r"serial FTS-0042", 60)
        term.expect(r"plan: 5 poses", 120)  # planning shares the CPU with the readers and the world
        term.expect(r"expected accuracy", 10)
        term.expect(r"Torque on and move the arm through 5 poses\? Keep hands and objects clear of it.*\[y/n\]", 10)
        term.type("y\r")
        for k in range(1, 6):
            term.expect(rf"pose {k}/5", 60)
            term.expect(r"sampled \d+ F/T frames, still", 60)
        term.expect(r"results: verdict", 30)
        term.expect(r"verdict: (good|poorly_excited)", 10)
        term.expect(r"Save the calibration to .*cal\.toml\?.*\[y/n\]", 10)
        term.type("y\r")
        term.expect(r"saved .*cal\.toml", 10)
        term.expect(r"plotted the fit: .*cal\.png", 30)
        code = term.finish(30)
    finally:
        term.kill()
    assert code in (0, 3)
    check_png(tmp_path / "cal.png", CALIBRATE_PX)
    record = json.loads(js.read_text())
    assert record["truth"]["mass_kg"] == 0.4 and record["truth"]["com_m"] == [0.0, 0.01, 0.05]
    assert record["verdict"] in ("good", "poorly_excited")
    assert abs(record["mass_kg"] - 0.4) <= 4 * record["std"]["mass_kg"] + 1e-3
    assert np.allclose(record["force_bias_N"], record["truth"]["force_bias_N"], atol=0.1)
    cal = load_calibration(out, scene="dxl-arm", sensor_serial="FTS-0042")
    assert cal.poses.shape == (5, 5) and cal.samples_per_pose == 50


def test_declining_torque_moves_nothing(tmp_path):
    out = tmp_path / "cal.toml"
    term = Terminal([*_ftc(), "calibrate", "--scene", "dxl-arm", "--sim", "--poses", "3", "--out", str(out)],
                    tmp_path)
    try:
        term.expect(r"Torque on and move the arm through 3 poses\?.*\[y/n\]", 150)
        term.type("n\r")
        term.expect(r"aborted: nothing moved", 20)
        code = term.finish(30)
    finally:
        term.kill()
    assert code == 1
    assert not out.exists()


# The emulated UR's wizard (no motion command over RTDE: the world's joint targets) runs on a user's URDF
# of the UR5e in tests/app/test_user_urdf.py.


def test_bad_sim_payload_is_a_usage_error():
    from typer.testing import CliRunner

    from ftc_hw.cli import app

    runner = CliRunner()
    for bad in ("mass=heavy,com=0,0,0", "mass=0.5,com=0,0", "m=0.5", "mass=-1,com=0,0,0"):
        result = runner.invoke(app, ["calibrate", "--scene", "dxl-arm", "--sim", "--sim-payload", bad])
        assert result.exit_code == 2, (bad, result.output)
        assert "mass=KG,com=X,Y,Z" in result.output
    result = runner.invoke(app, ["calibrate", "--scene", "dxl-arm", "--sim-payload", "mass=0.5,com=0,0,0"])
    assert result.exit_code == 2 and "--sim" in result.output


def test_jogging_a_ur_shows_the_live_joint_error_until_within_tolerance():
    """The bench flow for a UR: the wizard cannot move it and waits while a person jogs it, showing the
    joint error live. Here the person is a thread nudging the emulated arm's targets towards the pose
    (the RTDE receive path reports where it is); the wizard returns once it is there and held."""
    import io
    import threading

    from rich.console import Console

    from ftc_hw.app.calibration.calibrate import JOG_TOLERANCE, _jog
    from ftc_hw.app.calibration.device_session import DeviceSession
    from ftc_hw.scene import load_scene

    scene = load_scene("ur5e")
    with DeviceSession(scene, sim=True) as session:
        q0, _ = session.joint_state()
        goal = q0 + np.array([0.3, -0.2, 0.25, 0.0, 0.2, 0.1])
        done = threading.Event()

        def person() -> None:  # jogs in small steps, overshoots the last one a little, then corrects
            for s in np.linspace(0.0, 1.0, 30):
                if done.is_set():
                    return
                session.world.goal(q0 + s * (goal - q0) + (0.02 if 0.8 < s < 1.0 else 0.0))
                time.sleep(0.1)

        jogger = threading.Thread(target=person, daemon=True)
        screen = io.StringIO()
        t0 = time.monotonic()
        jogger.start()
        try:
            _jog(Console(file=screen, force_terminal=True, width=120), session, goal)
        finally:
            done.set()
            jogger.join(5)
        assert time.monotonic() - t0 >= 2.5  # not before the person got there
        err = np.abs(session.joint_state()[0] - goal).max()
        assert err < JOG_TOLERANCE
        assert "joint error" in ANSI.sub("", screen.getvalue())
