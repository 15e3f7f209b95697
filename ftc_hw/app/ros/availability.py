"""Whether the ``ros`` extra is installed, said once: every ROS entry point calls :func:`require_ros`
before its first ROS import."""
from __future__ import annotations

import importlib.util

INSTALL_HINT = ("install the ROS 2 extra: pip install 'ftc-hw[ros]' (scripts/bootstrap.sh installs it; "
                "ROS 2 Kilted's rclpy and messages as wheels from the package index, no ROS installation)")

# what ftc_hw.app.ros imports, each from the extra's wheels (pyproject.toml, [project.optional-dependencies])
REQUIRED = ("rclpy", "rosbags", "std_msgs", "geometry_msgs", "sensor_msgs", "visualization_msgs",
            "diagnostic_msgs", "std_srvs")


class RosUnavailable(RuntimeError):
    """A ROS option was asked for and the ``ros`` extra is not installed (the message names what is
    missing and how to install it)."""


def missing_modules() -> list[str]:
    """The extra's modules that cannot be imported here (empty when ROS is available)."""
    return [name for name in REQUIRED if importlib.util.find_spec(name) is None]


def require_ros(what: str) -> None:
    """Raise :class:`RosUnavailable` naming ``what`` asked for ROS when the extra is not installed."""
    missing = missing_modules()
    if missing:
        raise RosUnavailable(f"{what} needs ROS 2 ({', '.join(missing)} not installed): {INSTALL_HINT}")
