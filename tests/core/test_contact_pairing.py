"""Events that pair: a contact's onset, updates and offset carry one id; the offset carries the
contact's last estimate (never zeros) with its duration, peak force and impulse; a contact closed
because a stream was lost is flagged ``lost``. The pipeline fed directly (ideal world: its own model)."""
from __future__ import annotations

import numpy as np
import pytest

from ftc_hw.model import Contact
from ftc_hw.pipeline import ContactPipeline
from tests.conftest import settings

RATE_HZ = 1000.0


def _run(pipe, model, q, point, normal, profile, rng, t0_ns=0):
    """Feed one frame per entry of ``profile`` (the pushing force, N, along -normal); the events."""
    events, forces = [], []
    for i, f in enumerate(profile):
        t = t0_ns + int(i * 1e9 / RATE_HZ)
        contacts = [Contact("link3", point, -f * normal)] if f > 0 else []
        raw = model.predicted_wrench(q, level="gravity", contacts=contacts)
        raw = raw + rng.multivariate_normal(np.zeros(6), pipe.scene.sensor.noise_cov)
        events.extend(pipe.process(t, raw, q).events)
        forces.append(f)
    return events


def test_a_contact_s_events_share_an_id_and_its_offset_carries_its_last_estimate(link3_push):
    scene, model, q, point, normal = link3_push
    pipe = ContactPipeline(scene, settings(level="gravity", use_currents=False))
    rng = np.random.default_rng(1)
    push = np.concatenate([np.linspace(0, 30, 50), np.full(200, 30.0), np.linspace(30, 0, 50)])
    profile = np.concatenate([np.zeros(100), push, np.zeros(100), np.full(100, 20.0), np.zeros(100)])
    events = _run(pipe, model, q, point, normal, profile, rng)
    kinds = [e.kind for e in events]
    assert kinds.count("onset") == 2 and kinds.count("offset") == 2, kinds
    for cid in (1, 2):
        mine = [e for e in events if e.contact_id == cid]
        assert mine[0].kind == "onset" and mine[-1].kind == "offset"
        assert all(e.kind == "update" for e in mine[1:-1]) and len(mine) > 3
        sound = [e for e in mine[:-1] if set(e.flags) - {"uncertain"} <= {"grazing"}]
        offset, last = mine[-1], (sound or mine[:-1])[-1]  # the last sound estimate, not the release's
        assert offset.link == mine[0].link == "link3"
        assert np.array_equal(offset.point, last.point) and np.array_equal(offset.force, last.force)
        assert np.linalg.norm(offset.point - point) < 0.01 and offset.peak_force > 15.0
        assert offset.point_std.max() > 0 and "no_estimate" not in offset.flags
        durations = [e.duration_s for e in mine]
        assert durations == sorted(durations) and mine[0].duration_s >= 0.0
    first = [e for e in events if e.contact_id == 1][-1]
    # 300 frames pushed, the first and last few below the threshold; the offset comes n_off frames late
    assert 0.25 < first.duration_s < 0.32
    assert first.peak_force == pytest.approx(30.0, abs=1.5)
    assert first.impulse == pytest.approx(30.0 * 0.25, rel=0.1)  # 200 ms at 30 N plus two ramps


def test_a_lost_stream_closes_the_open_contact_with_a_lost_offset(link3_push):
    scene, model, q, point, normal = link3_push
    pipe = ContactPipeline(scene, settings(level="gravity", use_currents=False))
    rng = np.random.default_rng(2)
    events = _run(pipe, model, q, point, normal, np.concatenate([np.zeros(50), np.full(100, 25.0)]), rng)
    assert pipe.in_contact and [e.kind for e in events].count("offset") == 0
    lost = pipe.close_contact(10**9, lost=True)
    assert lost.kind == "offset" and "lost" in lost.flags and lost.contact_id == 1
    assert lost.link == "link3" and np.linalg.norm(lost.point - point) < 0.01
    assert lost.duration_s == pytest.approx(1.0 - 0.05, abs=0.01) and lost.peak_force == pytest.approx(25, abs=1.5)
    assert not pipe.in_contact
    # the stream comes back, still pushed: a new contact, a new id
    again = _run(pipe, model, q, point, normal, np.full(50, 25.0), rng, t0_ns=2 * 10**9)
    assert again[0].kind == "onset" and again[0].contact_id == 2
