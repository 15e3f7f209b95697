"""What every ROS test shares: a private ROS domain, discovery on this host only.

Each test session takes one domain id (``FTC_TEST_ROS_DOMAIN_ID``, else one drawn from the process id
in 60..99, clear of the default 0 and of ids people commonly use); every ROS process a test starts gets
the same environment (:func:`ros_env`), so its nodes see each other and nothing beyond this machine.
"""
from __future__ import annotations

import os

import pytest

# a rig file of ur5e's devices as a UR driver and the F/T broadcaster publish them (docs/ros.md)
UR_RIG = """
[ft]
kind = "ros-wrench"
topic = "/force_torque_sensor_broadcaster/wrench"
rate_hz = 1000.0
[arm]
kind = "ros-joint-state"
topic = "/joint_states"
rate_hz = 500.0
"""

DOMAIN_ID = int(os.environ.get("FTC_TEST_ROS_DOMAIN_ID", 60 + os.getpid() % 40))


def ros_env(base: dict[str, str] | None = None) -> dict[str, str]:
    """``base`` (else this process's environment) with the test domain and localhost discovery."""
    env = dict(os.environ if base is None else base)
    env["ROS_DOMAIN_ID"] = str(DOMAIN_ID)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    return env


@pytest.fixture(autouse=True)
def _private_ros_domain(monkeypatch):
    """This process's own nodes join the test domain too (rclpy reads the variables at init)."""
    for key, value in ros_env({}).items():
        monkeypatch.setenv(key, value)
