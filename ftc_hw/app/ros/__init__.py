"""ROS 2: the one package of ftc-hw that imports rclpy, ROS messages or rosbags (contract ``ros`` in
pyproject.toml). It needs the ``ros`` extra (``pip install 'ftc-hw[ros]'``; ``scripts/bootstrap.sh``
installs it); without it every ROS option fails with :class:`RosUnavailable`, which names what to install.

ROS follows the user's ROS environment as every ROS node does (``ROS_DOMAIN_ID``,
``ROS_AUTOMATIC_DISCOVERY_RANGE``); docs/ros.md."""
from __future__ import annotations

from ftc_hw.app.ros.availability import RosUnavailable, require_ros

__all__ = ["RosUnavailable", "require_ros"]
