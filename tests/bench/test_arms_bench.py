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


def test_rows_pass_between_the_bus_limit_with_the_host_s_turnaround_and_the_bus_limit():
    host_s = 1 / 2300  # this host's own cycle with bus time off

    def run(baud, rate, fast_rate, bus_time=True):
        out = {"baud": baud, "bus_time": bus_time}
        for label, r, fast in (("sync_read", rate, False), ("fast_sync_read", fast_rate, True)):
            lim = sync_read_limit(IDS, baud, fast=fast) if bus_time else None
            with_host = 1 / (1 / lim + host_s) if bus_time else None
            out[label] = {"reads_per_s": r, "failures": 0, "limit_per_s": lim, "limit_with_host_per_s": with_host}
        return out

    rows = _dxl_read_rows({"a": run(1_000_000, 650.0, 760.0), "b": run(57_600, 40.0, 58.0),
                           "c": run(1_000_000, 3000.0, 4000.0), "d": run(1_000_000, 480.0, 760.0),
                           "e": run(1_000_000, 3000.0, 4000.0, bus_time=False)})
    # within the bounds; 57 600 baud: 40/s is under 90 % of 45.5/s (the bus limit with the host's 0.43 ms);
    # 3000/s: bus time not spent (above the bus limit); 480/s: spent twice (under the lower bound)
    assert [ok for *_, ok in rows] == [True, False, False, False, True]
    assert "bus limit 806/s" in rows[0][1] and "turnaround 597/s" in rows[0][1] and "bus time off" in rows[4][0]
