"""``ftc bench arms``'s DYNAMIXEL bus limit and its rows, on made-up rates (nothing timed)."""
from __future__ import annotations

import pytest

from ftc_hw.bench.arms import _dxl_read_rows, sync_read_limit

pytestmark = pytest.mark.compute

IDS = [11, 12, 13, 14, 15]


def test_bus_limit_from_the_packet_sizes():
    # Sync Read of 126..135 from 5 servos: instruction 14 + 5 bytes, 5 status packets of 11 + 10 bytes
    assert sync_read_limit(IDS, 1_000_000) == pytest.approx(1e6 / (10 * (19 + 5 * 21)))  # 806/s
    assert sync_read_limit(IDS, 57_600) == pytest.approx(57_600 / (10 * 124))  # 46/s
    # Fast Sync Read: one status packet, 8 bytes + 5 x (error, id, 10 data bytes, CRC)
    assert sync_read_limit(IDS, 1_000_000, fast=True) == pytest.approx(1e6 / (10 * (19 + 8 + 5 * 14)))
    # Return Delay Time: once per status packet
    assert 1 / sync_read_limit(IDS, 1_000_000, 500.0) == pytest.approx(1.24e-3 + 5 * 500e-6)


def test_rows_pass_within_ten_percent_of_the_limit_and_say_both():
    def run(baud, rate, fast_rate, bus_time=True):
        lim = (sync_read_limit(IDS, baud), sync_read_limit(IDS, baud, fast=True)) if bus_time else (None, None)
        return {"baud": baud, "bus_time": bus_time,
                "sync_read": {"reads_per_s": rate, "failures": 0, "limit_per_s": lim[0]},
                "fast_sync_read": {"reads_per_s": fast_rate, "failures": 0, "limit_per_s": lim[1]}}

    rows = _dxl_read_rows({"a": run(1_000_000, 750.0, 990.0), "b": run(57_600, 40.0, 58.0),
                           "c": run(1_000_000, 3000.0, 4000.0, bus_time=False)})
    assert [ok for *_, ok in rows] == [True, False, True]
    assert "limit 806/s" in rows[0][1] and "limit 46/s" in rows[1][1] and "bus time off" in rows[2][0]
