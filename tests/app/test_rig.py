"""The one rig builder: a scene's devices picked by role from the adapter registry, opened, waited for."""
from __future__ import annotations

from dataclasses import replace

import pytest

from ftc_hw.app.setup.rig import RigError, build_rig, pick_device
from ftc_hw.devices.can_ft import CanFTAdapter
from ftc_hw.devices.dynamixel import DynamixelArm
from ftc_hw.devices.ft300 import FT300Adapter
from ftc_hw.devices.registry import kinds, roles_of
from ftc_hw.devices.serial_stream import SerialStreamFTAdapter
from ftc_hw.devices.ur import URArm
from ftc_hw.scene import DeviceSpec, load_rig_scene, load_scene
from ftc_hw.sim_devices.emulator import sample_number
from ftc_hw.sim_devices.host import WorldHost
from tests.ur_flange import flange_scene

pytestmark = pytest.mark.timeout(120)


def _addressed(spec: DeviceSpec) -> DeviceSpec:
    """The scene's device as a user's own hardware would be declared: with an address."""
    address = "127.0.0.1:1" if spec.transport in ("tcp", "modbus-tcp") else "/dev/ttyFTC0"
    return replace(spec, address=address)


@pytest.mark.realtime
@pytest.mark.parametrize(("scene_name", "ft_class", "arm_class"), [
    ("ur5e", CanFTAdapter, URArm), ("dxl-arm", FT300Adapter, DynamixelArm)])
def test_a_scene_rig_is_its_f_t_sensor_and_its_arm(scene_name, ft_class, arm_class):
    scene = load_scene(scene_name)
    with pytest.raises(RigError) as info:
        build_rig(scene)  # the shipped scenes name no hardware address: an emulator's endpoint is needed
    says = str(info.value)  # every device without one, what its address is, and how to give it
    assert says.startswith("no address for device 'ft'") and "and 'arm'" in says, says
    assert "--device ft." in says and "--device arm.address=" in says and "--rig" in says, says
    rig = build_rig(scene, devices=[_addressed(pick_device(scene, r)) for r in ("ft", "arm")])
    assert isinstance(rig.ft, ft_class) and isinstance(rig.arm, arm_class)
    assert [a.role for a in rig.adapters] == ["ft", "arm"]
    rig.close()  # never opened: closing is harmless


@pytest.mark.compute
def test_overrides_put_the_rig_where_they_say():
    scene = load_rig_scene("ur5e", ["ft.channel=/dev/ttyFTC1", "ft.base_id=9", "arm.address=192.0.2.10"])
    rig = build_rig(scene)
    assert rig.ft.channel == "/dev/ttyFTC1" and rig.ft.codec.base_id == 9 and rig.arm.host == "192.0.2.10"
    rig.close()


@pytest.mark.compute
def test_a_ur_reading_its_flange_sensor_is_the_rig_s_f_t_sensor_and_its_arm(tmp_path):
    scene = flange_scene(tmp_path)  # a flange sensor the pipeline uses, no F/T device of its own
    arm = pick_device(scene, "arm")
    assert pick_device(scene, "ft") is arm and roles_of(arm, scene) == {"ft", "arm"}
    with pytest.raises(RigError, match=r"^no address for device 'arm' \(ur-rtde: [^)]*\): give it with"):
        build_rig(scene)  # named once
    rig = build_rig(scene, endpoints={"arm": {"address": "192.0.2.10"}})  # both roles: one adapter
    assert len(rig.adapters) == 1 and rig.ft is rig.arm and isinstance(rig.arm, URArm)
    assert rig.arm.topics == ("joints/arm", "wrench/arm") and "ft_raw_wrench" in rig.arm.variables
    assert list(rig.arm.ft_range) == list(scene.sensor.range)
    # the device's own say, the sensing the pipeline uses, and an F/T device of the scene's own each win
    off = replace(scene, devices=(replace(arm, params={**arm.params, "ft": False}),))
    narrowed = scene.with_sensing(["currents"])
    own_ft = replace(scene, devices=(load_scene("ur5e").devices[0], arm))
    for other in (off, narrowed, own_ft):
        assert roles_of(other.devices[-1], other) == {"arm"}
    with pytest.raises(RigError, match="declares no F/T sensor device"):
        build_rig(off, endpoints={"arm": {"address": "192.0.2.10"}})
    assert pick_device(own_ft, "ft").kind == "ft-can"
    assert not build_rig(narrowed, roles=("arm",), endpoints={"arm": {"address": "192.0.2.10"}}).arm.ft
    ur5e = load_scene("ur5e")
    assert roles_of(ur5e.devices[1], ur5e) == {"arm"} and pick_device(ur5e, "ft").kind == "ft-can"


@pytest.mark.compute
def test_a_scene_without_an_arm_device_says_so():
    scene = load_scene("leng2016")
    assert pick_device(scene, "arm") is None
    with pytest.raises(RigError, match=r"declares no arm device \(kinds: " + ", ".join(kinds("arm"))):
        build_rig(scene)
    assert isinstance(build_rig(scene, devices=[_addressed(pick_device(scene, "ft"))]).ft, SerialStreamFTAdapter)


@pytest.mark.compute
def test_an_unknown_kind_is_a_rig_error():
    scene = load_scene("leng2016")
    with pytest.raises(RigError, match="no adapter for device kind 'laser'"):
        build_rig(scene, devices=[DeviceSpec("x", "laser", "serial", "/dev/null")])


@pytest.mark.realtime
def test_a_device_that_does_not_answer_is_named_with_its_counters(tmp_path):
    scene = load_scene("leng2016")
    spec = DeviceSpec("ft", "ft-serial-stream", "serial", str(tmp_path / "no-such-port"), {"format": "ftc-1k"})
    rig = build_rig(scene, devices=[spec], timeout=0.5)
    says = r"ft \(ft-serial-stream\) did not connect within 0.5 s: .*connect_failures"
    with pytest.raises(RigError, match=says), rig:
        pass
    assert not rig.ft.connected.is_set()  # closed on the way out


@pytest.mark.realtime
def test_a_rig_on_a_hosted_world_streams_the_world_samples():
    with WorldHost("leng2016", "hold", devices=["ft"], noise=False) as world:
        rig = build_rig(world.scene, endpoints=world.endpoints, roles=("ft",), timeout=20.0)
        with rig:
            rig.wait(data=True)
            frame = rig.bus.latest(rig.ft.topic)
        reader = world.ft_reader(from_start=True)
        published = {sample_number(float(r[0]), world.scene.sensor.rate_hz): r[1:7] for r in reader.new()}
    assert frame is not None and frame.seq in published
    assert abs(frame.wrench - published[frame.seq]).max() <= 1e-4  # the ftc-1k encoding's resolution
