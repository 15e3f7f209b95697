"""Contact events (ContactPipeline._event): an estimate the event cannot carry (no link, or an infinite
uncertainty) still gives its event, flagged ``no_estimate``, instead of losing it (an onset among them)."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from ftc_hw.pipeline import ContactPipeline

event = ContactPipeline._event


def estimate(link, std, contact=True):
    return SimpleNamespace(contact=contact, link=link, point=np.array([0.1, 0.2, 0.3]),
                           force=np.array([0.0, 0.0, -5.0]), point_std=np.asarray(std, dtype=float),
                           flags=("grazing",))


DET = SimpleNamespace(probability=0.9)


def test_a_good_estimate_is_carried_as_it_is():
    ev = event(7, "onset", estimate("link3", [0.001, 0.002, 0.003]), DET)
    assert ev.link == "link3" and ev.point.tolist() == [0.1, 0.2, 0.3] and ev.flags == ("grazing",)


def test_an_infinite_uncertainty_gives_a_flagged_event():
    ev = event(7, "update", estimate("link3", [np.nan, np.inf, np.inf]), DET)
    assert ev.kind == "update" and ev.t_host_ns == 7 and ev.link == "link3"
    assert not ev.point.any() and not ev.point_std.any() and ev.flags == ("grazing", "no_estimate")
    assert ev.probability == 0.9


def test_an_estimate_without_a_link_gives_a_flagged_event():
    ev = event(9, "onset", estimate(None, [0.0, 0.0, 0.0], contact=False), DET)
    assert ev.kind == "onset" and ev.link == "unknown" and "no_estimate" in ev.flags
