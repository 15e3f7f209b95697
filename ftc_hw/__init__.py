"""ftc-hw: contact sensing from one 6-axis force/torque sensor, on real and emulated devices."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("ftc-hw")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+local"
