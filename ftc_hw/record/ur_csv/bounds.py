"""What a UR recording's values may be. A row with a value past these is not a reading of a UR arm
(a corrupted row: real logs hold rows of 1e300) and is skipped, counted by field. Wide on purpose:
they catch garbage, never a real reading."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PhysicalBounds:
    """Limits of a row's values, in SI units (degrees Celsius for temperatures)."""

    # Twice the e-Series joints' working range of +-360 deg (UR3e/UR5e/UR10e/UR16e datasheets), so a
    # CB3's endless wrist 3 past one more turn still reads.
    q_rad: float = 4 * math.pi
    # Twice the fastest UR joint (UR3e wrists, 360 deg/s: its datasheet).
    qd_rad_s: float = 4 * math.pi
    # ESTIMATE: ur5e's scene reaches 150 N m / 13 N m/A = 11.5 A at its joint torque limit; 50 A at
    # the arm's 48 V bus would be 2.4 kW in one joint, past what an e-Series arm draws in all.
    current_a: float = 50.0
    # ESTIMATE: several times the largest joint torque and wrench any UR arm produces or bears (its
    # joints are rated hundreds of N m; its flange sensor tens of N and N m).
    force_n: float = 1.0e4
    torque_nm: float = 2.0e3
    # ESTIMATE: a joint outside -50..200 degC is not running (UR's rated ambient is 0-50 degC).
    temperature_c: tuple[float, float] = (-50.0, 200.0)
    # ESTIMATE: 300 years of controller uptime; also admits a host's Unix time (~1.8e9 s), which some
    # forks of record.py write in place of the controller's timestamp.
    time_s: float = 1.0e10

    def within(self, field: str, values: np.ndarray) -> np.ndarray:
        """Per row (``values``: (m, k)), whether every value of ``field`` is within its limits."""
        if field == "timestamp":
            return ((values >= 0.0) & (values <= self.time_s)).all(axis=1)
        if field == "joint_temperatures":
            lo, hi = self.temperature_c
            return ((values >= lo) & (values <= hi)).all(axis=1)
        if field in ("ft_raw_wrench", "actual_TCP_force"):
            return ((np.abs(values[:, :3]) <= self.force_n).all(axis=1)
                    & (np.abs(values[:, 3:]) <= self.torque_nm).all(axis=1))
        limit = {"actual_q": self.q_rad, "actual_qd": self.qd_rad_s, "actual_current": self.current_a,
                 "target_current": self.current_a, "target_moment": self.torque_nm}[field]
        return (np.abs(values) <= limit).all(axis=1)


DEFAULT_BOUNDS = PhysicalBounds()
