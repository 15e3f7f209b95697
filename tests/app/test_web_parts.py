"""The live page's parts that need no browser: the truth file's tail, the bounded queue to the page
(drops its oldest, counted), and scene nodes updated in place, only what changed."""
from __future__ import annotations

import json

import numpy as np
import pytest

from ftc_hw.app.web.feed import QUEUE_TICKS, PageProcess, WebOptions
from ftc_hw.app.web.scene import DrawnEntity
from ftc_hw.app.web.state import TruthTail
from ftc_hw.record.foxglove_messages import color, entity, pose, vec3

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
