"""A recording process run until it says ``ready``, then SIGKILLed: what a pulled plug leaves."""
from __future__ import annotations

import os
import signal
import subprocess
import time


def kill_when_ready(args: list[str], after_s: float) -> int:
    """Run ``args``, wait for its ``ready`` line, let it go on ``after_s``, SIGKILL it; its return code."""
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(after_s)
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
    return proc.returncode
