"""The cell's body limits file (docs/limits.md): the built-in ISO/TS 15066 regions, a cell's overrides, zones and
links, the limits through JSON (recordings), and a malformed file as a LimitsError naming the line and the key."""
from __future__ import annotations

import numpy as np
import pytest

from ftc_hw.bus import ContactEvent, LimitCheck
from ftc_hw.bus.wire import decode, encode
from ftc_hw.record.events import event_record, limit_check_of
from ftc_hw.record.schemas import decode as decode_json
from ftc_hw.record.schemas import encode as encode_json
from ftc_hw.scene.limits import CellLimits, LimitsError, builtin_limits, load_limits

pytestmark = pytest.mark.compute


def _file(tmp_path, text: str):
    p = tmp_path / "cell.toml"
    p.write_text(text, encoding="utf-8")
    return p


def test_the_builtin_regions_are_the_standards_table():
    b = builtin_limits()
    assert len(b.regions) == 12 and b.default_region == "abdomen" and not b.links and not b.zones
    chest = b.regions["chest"]  # ISO/TS 15066 Table A.2 / A.3
    assert (chest.quasi_static_n, chest.transient_n, chest.spring_constant_n_per_m, chest.effective_mass_kg) == (
        140.0, 280.0, 25000.0, 40.0)
    for r in b.regions.values():  # transient twice the quasi-static, or none permitted (skull, face)
        assert r.transient_n in (0.0, 2 * r.quasi_static_n)
    assert b.regions["face"].transient_n == 0.0


def test_a_cell_overrides_a_key_and_assigns_links_and_zones(tmp_path):
    cell = load_limits(_file(tmp_path, """
[limits]
default_region = "hands_fingers"

[regions.chest]
quasi_static_n = 100.0

[links]
forearm = "lower_arms_wrists"

[[zones]]
region = "face"
sphere = { center = [0.5, 0.0, 1.0], radius = 0.2 }

[[zones]]
region = "chest"
box = { center = [0.5, 0.0, 1.0], half_size = [0.3, 0.3, 0.3] }
"""))
    chest = cell.regions["chest"]
    assert (chest.quasi_static_n, chest.transient_n) == (100.0, 280.0)  # the rest from the built-in
    assert cell.region_at("forearm", np.zeros(3))[0].name == "lower_arms_wrists"
    assert cell.region_at("upper_arm", np.zeros(3)) == (cell.regions["hands_fingers"], "default")
    # in both zones: the stricter (face, 65 N); in the box alone: the chest, whatever the link
    assert cell.region_at("forearm", np.array([0.5, 0.1, 1.0])) == (cell.regions["face"], "zone")
    assert cell.region_at("forearm", np.array([0.75, 0.0, 1.0]))[0].name == "chest"
    again = CellLimits.from_json(cell.to_json())
    assert again.to_json() == cell.to_json()


@pytest.mark.parametrize(("text", "line", "key"), [
    ("[limits]\ndefault_region = \"nope\"\n", 2, "limits.default_region"),
    ("[regions.chest]\nquasi_static_n = -1\n", 2, "regions.chest.quasi_static_n"),
    ("[regions.chest]\nspring_constant_n_per_m = 0\n", 2, "regions.chest.spring_constant_n_per_m"),
    ("[regions.chest]\nquasi_static = 3\n", 2, "regions.chest.quasi_static"),
    ("[regions.mine]\nquasi_static_n = 3.0\n", 1, "regions.mine.transient_n"),
    ("\n[links]\nforearm = \"elbow\"\n", 3, "links.forearm"),
    ("[[zones]]\nregion = \"chest\"\nbox = { center = [0, 0], half_size = [1, 1, 1] }\n", 3, "zones[0].box.center"),
    ("[[zones]]\nregion = \"chest\"\n", 1, "zones[0]"),
    ("[limits]\nbase = \"iso-9999\"\n", 2, "limits.base"),
    ("[limits\n", 1, ""),
])
def test_a_malformed_file_names_its_line_and_key(tmp_path, text, line, key):
    with pytest.raises(LimitsError) as err:
        load_limits(_file(tmp_path, text))
    assert (err.value.line, err.value.key) == (line, key), str(err.value)
    assert str(err.value).startswith(f"{tmp_path / 'cell.toml'}:{line}")


def test_a_link_the_arm_does_not_have_is_named(tmp_path):
    cell = load_limits(_file(tmp_path, '[links]\nelbow = "chest"\n'))
    with pytest.raises(LimitsError, match="links.elbow: no link 'elbow'"):
        cell.check_links(("base", "forearm"))


def test_an_event_with_its_limits_goes_through_every_format():
    check = LimitCheck("chest", "zone", "quasi_static", True, 140.0, -12.5, 8.25, 0.31, 0.52)
    ev = ContactEvent.make(10, "exceedance", "forearm", [0.1, 0.2, 0.3], [1.0, 2.0, 152.0], contact_id=3,
                           limits=check)
    for back in (decode(encode(ev)), decode_json(*encode_json(ev))):
        assert back.kind == "exceedance" and back.limits == check
    assert limit_check_of(event_record(ev)["limits"]) == check
    plain = ContactEvent.make(10, "update", "forearm", [0.1, 0.2, 0.3], [1.0, 2.0, 3.0])
    assert decode(encode(plain)).limits is None and "limits" not in event_record(plain)
