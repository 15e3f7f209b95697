"""ftc-hw: contact sensing from one 6-axis force/torque sensor, on real and emulated devices."""

import os
from importlib.metadata import PackageNotFoundError, version

# numpy's OpenBLAS starts a worker thread per core, and they spin after every call: on a cell's small
# computer they take the cores from the device readers, the world and the other processes, where our
# matrices gain little from them. One thread unless the user says otherwise (set before numpy loads;
# inherited by every process ftc starts).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

try:
    __version__ = version("ftc-hw")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+local"
