"""The application, by concern: ``ftc demo`` (``demo``), the monitor session and ``ftc replay``
(``monitor``), the live page (``web``), calibration and identification (``calibration``), the devices
served on Zenoh and read from there (``serving``), and what they share or set up (``setup``: the rig
builder, the device probe, the kernels' warm-up, vendor meshes and vendor libraries' output). Their
layers: docs/architecture.md."""
