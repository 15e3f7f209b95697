"""Vendor libraries' C++ lines on stderr (ur_rtde's receive thread) reach the user as one clear line."""
from __future__ import annotations

import subprocess
import sys

import pytest

from ftc_hw.app.setup.vendor_output import translate

pytestmark = pytest.mark.compute  # computes only (nothing timed): runs with the others on every core

RAW = "RTDEReceiveInterface boost system Exception: (asio.misc:2) End of file"


def test_known_lines_are_rewritten_and_others_pass():
    text, vendor = translate(RAW)
    assert vendor and text == "ur_rtde: the controller's RTDE stream dropped (End of file); the arm adapter reconnects"
    assert translate("something else") == ("something else", False)


def test_a_line_written_to_descriptor_2_by_native_code_is_rewritten_and_counted():
    # os.write on fd 2 is what C++'s std::cerr does: below Python's sys.stderr
    code = f"""
import os, sys
from ftc_hw.app.setup.vendor_output import vendor_stderr
with vendor_stderr() as seen:
    os.write(2, b"{RAW}\\n")
    os.write(2, b"plain line\\n")
    print("python", file=sys.stderr)
print(dict(seen.counts))
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.splitlines() == [translate(RAW)[0], "plain line", "python"]
    assert "RTDEReceiveInterface" not in proc.stderr
    assert proc.stdout.strip() == str({translate(RAW)[0]: 1})


def test_the_block_ends_at_once_though_a_process_it_started_holds_the_pipe_and_its_later_lines_pass():
    # a process started in the block (a world, an emulator, multiprocessing's resource tracker) inherits
    # descriptor 2: the block's end used to wait 2 s for it to close the pipe
    code = """
import os, subprocess, sys, time
from ftc_hw.app.setup.vendor_output import vendor_stderr
with vendor_stderr():
    child = subprocess.Popen([sys.executable, "-c", "import os, time; time.sleep(1.5); os.write(2, b'late line\\\\n')"])
    os.write(2, b"partial")
    t0 = time.monotonic()
ended = time.monotonic() - t0
print("after the block", file=sys.stderr, flush=True)
child.wait()
time.sleep(0.3)
print(round(ended, 3))
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert float(proc.stdout.strip()) < 0.5, proc.stdout
    assert proc.stderr.splitlines() == ["partial", "after the block", "late line"], proc.stderr
