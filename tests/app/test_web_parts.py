"""The live page's parts that need no browser: the truth file's tail, the bounded queue to the page
(drops its oldest, counted), and scene nodes updated in place, only what changed."""
from __future__ import annotations

import json

import numpy as np
import pytest
import viser

from ftc_hw.app.web.feed import QUEUE_TICKS, PageProcess, WebOptions
from ftc_hw.app.web.page import Page
from ftc_hw.app.web.scene import DrawnEntity
from ftc_hw.app.web.state import TruthTail, page_setup
from ftc_hw.bus import ContactEvent
from ftc_hw.record.events import event_record
from ftc_hw.record.foxglove_messages import color, contact_entity, entity, pose, vec3
from ftc_hw.record.foxglove_view import FoxgloveView
from ftc_hw.scene import load_scene

pytestmark = pytest.mark.realtime  # against the wall clock: ./run-tests runs it alone, after the others


def test_the_truth_tail_gives_the_newest_complete_line(tmp_path):
    path = tmp_path / "truth.jsonl"
    tail = TruthTail(path)
    assert tail.latest() is None  # no file yet: the world has not started
    rec = {"t": 0.1, "contact": True, "link": "link3", "point": [0.1, 0.2, 0.3], "force": [1.0, 0.0, 0.0]}
    with open(path, "w", encoding="utf-8") as f:
        f.write(json.dumps({**rec, "contact": False, "link": None}) + "\n" + json.dumps(rec) + "\n")
        f.write('{"t": 0.3, "cont')  # a line being written
        f.flush()
        assert tail.latest() == {"contact": True, "link": "link3", "point": [0.1, 0.2, 0.3], "force": [1.0, 0.0, 0.0]}
        assert tail.latest() is None  # nothing new and complete
        f.write('act": false, "link": null, "point": null, "force": null}\n')
        f.flush()
        assert tail.latest() == {"contact": False, "link": None, "point": None, "force": None}
    tail.close()


def test_a_full_queue_to_the_page_drops_its_oldest_ticks():
    page = PageProcess({}, WebOptions())  # not started: nobody takes the ticks
    try:
        for i in range(QUEUE_TICKS + 5):
            page.put({"t": i})
        assert page.drops == 5
        got = [page.inbox.get(timeout=2)["t"] for _ in range(QUEUE_TICKS)]
        assert got == list(range(5, QUEUE_TICKS + 5))
    finally:
        page.close()


class _Scene:
    """viser's scene API as far as DrawnEntity uses it: handles that log what is set."""

    def __init__(self) -> None:
        self.log: list[tuple] = []

    def __getattr__(self, name: str):
        if not name.startswith("add_"):
            raise AttributeError(name)
        scene = self

        class Handle:
            def __init__(self, node: str) -> None:
                object.__setattr__(self, "node", node)

            def __setattr__(self, key, value) -> None:
                scene.log.append(("set", self.node, key))

            def remove(self) -> None:
                scene.log.append(("remove", self.node))

        def add(node: str, **kwargs):
            scene.log.append((name, node))
            return Handle(node)

        return add


def _contact(p, radius: float = 0.01):
    red = color(1, 0, 0)
    return entity(0, "world", "c", spheres=[{"pose": pose(p), "size": vec3(np.full(3, radius)), "color": red}])


def test_an_entity_drawn_again_sets_only_what_changed():
    scene = _Scene()
    drawn = DrawnEntity(scene, "/contacts/1")
    drawn.draw(_contact([0.1, 0.2, 0.3]))
    assert scene.log == [("add_icosphere", "/contacts/1/sphere0")]
    scene.log.clear()
    drawn.draw(_contact([0.1, 0.2, 0.3]))
    assert scene.log == []  # nothing changed: nothing sent
    drawn.draw(_contact([0.1, 0.25, 0.3]))
    assert scene.log == [("set", "/contacts/1/sphere0", "position")]
    scene.log.clear()
    drawn.draw(entity(0, "world", "c", texts=[]))  # other primitives: drawn anew
    assert scene.log == [("remove", "/contacts/1/sphere0")]


def _ticks(view) -> list[dict]:
    """Three ticks as the feed makes them: an onset, its update, then none."""
    ticks = []
    for i, kind in enumerate(("onset", "update", None)):
        tick = {"t": 1.0 + 0.1 * i, "t_host_ns": 1_000_000_000 + i, "external": [1.0 * i, 0, 0, 0, 0, 0],
                "d2": 10.0 * i, "threshold": 5.0}
        if kind is not None:
            ev = ContactEvent.make(tick["t_host_ns"], kind, view.arm.link_names[-1], [0.1, 0.0, 0.2 + 0.1 * i],
                                   [0.0, 0.0, 20.0], [0.01, 0.01, 0.01], contact_id=1)
            rec = event_record(ev)
            rec["entity"] = contact_entity(ev, np.eye(4), marker_m=view.marker_m, m_per_n=view.contact_m_per_n,
                                           max_m=view.reach, lifetime_s=view.contact_lifetime_s)
            tick["events"] = [rec]
        ticks.append(tick)
    return ticks


def _drawn(view, *batches: list[dict]) -> dict:
    """What a page shows after applying each of ``batches`` as one update (a server of its own)."""
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        page = Page(server, page_setup(view, "t"))
        for batch in batches:
            page.apply(*batch)
        return {"series": list(page.series), "events": list(page.events), "panel": page.contact_md.content,
                "contacts": {cid: (c["t"], c["ev"]["kind"]) for cid, c in page.contacts.items()}}
    finally:
        server.stop()


def test_ticks_that_waited_are_drawn_as_one_update_with_every_event_and_sample():
    view = FoxgloveView(load_scene("dxl-arm"))
    ticks = _ticks(view)
    batched, one_by_one = _drawn(view, ticks), _drawn(view, *([t] for t in ticks))
    panel = batched.pop("panel")
    assert batched == {k: v for k, v in one_by_one.items() if k != "panel"}
    assert len(batched["series"]) == 3 and "**onset**" in batched["events"][0][1]
    assert batched["contacts"] == {1: (pytest.approx(1.1), "update")}
    assert "CONTACT #1" in panel and "point 100.0 0.0 300.0 mm" in panel  # the newest estimate at once
