"""``--reflex stop`` on an arm read from ROS topics: the monitor calls the driver's stop service
(``stop_service``, std_srvs/Trigger) and the arm stops. ``ftc ros publish`` plays ur_robot_driver, its
dashboard client's ``/dashboard_client/stop`` too (the emulated UR stopped through ur_rtde, as the
dashboard's ``stop`` stops a real one's program); each node in its own process, the domain private
(conftest.ros_env). The world's truth says the arm, sweeping at the onset, stood still 300 ms later."""
from __future__ import annotations

import json
import re
import signal
import subprocess
import sys

import numpy as np
import pytest

from ftc_hw.record.events import read_events, read_truth

from .conftest import UR_RIG, ros_env

pytestmark = [pytest.mark.realtime, pytest.mark.timeout(180)]


def ftc(*args: str, **kw) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "ftc_hw", *args], env=ros_env(), text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, **kw)


def test_the_stop_reflex_calls_the_drivers_stop_service_and_the_arm_stops(tmp_path):
    (tmp_path / "ros.toml").write_text(UR_RIG + 'stop_service = "/dashboard_client/stop"\n')
    events, truth = tmp_path / "e.jsonl", tmp_path / "truth.jsonl"
    pub = ftc("ros", "publish", "--scene", "ur5e", "--sim", "--scenario", "sweep-with-collision", "--reality",
              "ideal", "--duration", "3", "--truth", str(truth))
    mon = ftc("monitor", "--scene", "ur5e", "--rig", str(tmp_path / "ros.toml"), "--duration", "120", "--events",
              str(events), "--no-view", "--readers", "thread", "--reflex", "stop")
    try:
        services = json.loads(pub.stdout.readline())["services"]
        assert services == [{"service": "/dashboard_client/stop", "type": "std_srvs/srv/Trigger"}]
        pub_err = pub.communicate(timeout=120)[1]
    finally:
        pub.kill()
        mon.send_signal(signal.SIGTERM)
        mon_out = " ".join(mon.communicate(timeout=60)[0].split())
    # one stop a contact; a provisional onset the pipeline did not confirm would stop it once more (counted)
    calls = re.search(r"/dashboard_client/stop: (\d+) calls, 0 failed", pub_err)
    assert pub.returncode == 0 and calls and int(calls.group(1)) >= 1, pub_err
    n = int(calls.group(1))
    assert f"reflex stop: {n} sent" in mon_out and f"'stops': {n}" in mon_out, mon_out[-3000:]
    (onset,) = [e for e in read_events(events) if e["kind"] == "onset"]
    rows = read_truth(truth)
    t = np.array([r["t_host_ns"] for r in rows])
    q = np.array([r["q"] for r in rows])
    speed = np.r_[0.0, np.linalg.norm(np.diff(q, axis=0), axis=1) / (np.diff(t) * 1e-9)]  # rad/s, all joints
    k = np.searchsorted(t, onset["t_host_ns"])
    assert speed[k - 100:k].max() > 0.02  # it was sweeping
    assert speed[np.searchsorted(t, onset["t_host_ns"] + 300_000_000):].max() < 1e-3  # and stood still
