"""``ftc devices probe``: what answers where, found on emulators in their own processes through the real
client libraries (pymodbus, dynamixel_sdk, python-can, a plain socket for RTDE and the dashboard)."""
from __future__ import annotations

from dataclasses import replace

import pytest

from ftc_hw.app.setup.probe import ProbePlan, plan_probe, probe
from ftc_hw.scene import load_rig_scene, load_scene
from ftc_hw.sim_devices.host import WorldHost

pytestmark = [pytest.mark.realtime, pytest.mark.timeout(120)]


def test_a_plan_tries_where_the_scene_and_the_options_say():
    scene = load_rig_scene("dxl-arm", ["ft.address=/dev/ttyFT", "arm.address=/dev/ttyDXL"])
    plan = plan_probe(scene, ports=["/dev/ttyX"], can=["socketcan:can0", "/dev/ttyACM0"], addresses=["192.0.2.1"],
                      bauds=[57600])
    got = [(c.kind, c.where, dict(c.options)) for c in plan.candidates]
    assert got == [("ft300", "/dev/ttyFT", {"baudrate": 19200, "device_id": 9}),
                   ("dynamixel", "/dev/ttyDXL", {"bauds": (1_000_000, 57600)}),
                   ("ft300", "/dev/ttyX", {}), ("dynamixel", "/dev/ttyX", {"bauds": (57600,)}),
                   ("can", "can0", {"interface": "socketcan"}), ("can", "/dev/ttyACM0", {}),
                   ("ur", "192.0.2.1", {}), ("rdt", "192.0.2.1", {})]
    unlocated = plan_probe(load_scene("ur5e"))
    assert not unlocated.candidates and len(unlocated.notes) == 2
    assert "ft (ft-can): no address" in unlocated.notes[0] and "--device ft.channel=" in unlocated.notes[0]


def test_probe_finds_the_emulated_ft300_servos_netft_and_ur_controller():
    dxl = load_scene("dxl-arm")
    ft300, servos = replace(dxl.devices[0], name="ft300"), replace(dxl.devices[1], name="servos")
    rdt = replace(load_scene("ur5e-netft").devices[0], name="box")
    with WorldHost("ur5e", "hold", devices=["ft", "arm", ft300, servos, rdt], noise=False) as world:
        ep = world.endpoints
        box = ep["box"]
        ft_port, dxl_port, ur = ep["ft300"]["endpoint"], ep["servos"]["endpoint"], ep["arm"]["address"]
        plan = ProbePlan()
        plan.add("ft300", ft_port)
        plan.add("ft300", dxl_port)  # a DYNAMIXEL bus is no FT 300
        plan.add("dynamixel", dxl_port, bauds=(57600, 1_000_000))
        plan.add("can", ep["ft"]["channel"])
        plan.add("ur", ur)
        plan.add("ur", "127.0.0.98")  # nobody there
        plan.add("rdt", box["host"], port=box["port"], http_port=box["http_port"])  # 49152 and 80 as a rule
        plan.add("rdt", "127.0.0.253")  # nobody there
        found, tried = probe(plan, timeout=0.3)
    by = {(f.what, f.where): f.identity for f in found}
    assert set(by) == {("FT 300", ft_port), ("DYNAMIXEL", dxl_port), ("Net F/T", ep["ft"]["channel"]),
                       ("UR controller", ur), ("Net F/T (RDT)", box["host"])}, tried
    netft = by[("Net F/T (RDT)", box["host"])]
    assert netft["counts_per_force"] == "100000/N" and netft["counts_from"] == "/netftcalapi.xml calcpf/calcpt"
    assert "software_bias" not in netft  # none left in the box
    assert by[("FT 300", ft_port)]["firmware"] == "FTS-3.0.1" and by[("FT 300", ft_port)]["serial"] == "FTS-0042"
    servo = by[("DYNAMIXEL", dxl_port)]
    assert servo["baudrate"] == 1_000_000 and servo["ids"] == [11, 12, 13, 14, 15]
    assert set(servo["models"].values()) == {"XM430-W350"}
    assert by[("Net F/T", ep["ft"]["channel"])]["base_id"] == 8
    assert by[("UR controller", ur)]["serial"] == "20205500001" and "URSoftware 5.9" in by[("UR controller", ur)][
        "version"]
    assert any("at 57600 bit/s: no servo answered" in t for t in tried), tried
    assert any(t.startswith("UR controller at 127.0.0.98: RTDE") and "does not answer" in t for t in tried), tried
