"""ROS 2 bags in, the way a user runs them: bags as ``ros2 bag record`` keeps a cell's drivers' topics
(ur_robot_driver's /joint_states with currents and a flange wrench, franka_ros2's /franka/joint_states with
measured torques, a Net F/T driver's wrench under a UR5e's base), MCAP and sqlite3, with bad messages, written
from the simulated world (tests/app/ros/world_bag.py), then ``ftc identify BAG...`` and ``ftc replay BAG``
through the CLI (in this process: one import of the pipeline for all). Nothing is published: no ROS node runs."""
from __future__ import annotations

import re

import numpy as np
import pytest
from typer.testing import CliRunner

from ftc_hw.app.ros.bag_form import is_ros_bag
from ftc_hw.app.ros.bag_read import BagError, read_bag
from ftc_hw.app.ros.topic_map import TopicMapError, default_map, load_topic_map
from ftc_hw.calibration.file import load_calibration
from ftc_hw.cli import app
from ftc_hw.scene import load_scene
from ftc_hw.sim_devices.world import with_reality
from tests.app.ros.world_bag import Driver, storage_file, write_bag
from tests.ur_world_csv import run_world

pytestmark = pytest.mark.compute  # the world runs in this process; bags on disk; nothing is timed

UR10E = load_scene("ur10e")
WORLD = with_reality(UR10E, "typical", seed=3)
UR_ORDER = (2, 1, 0, 3, 4, 5)  # ur_robot_driver's /joint_states lists the joints in another order than the arm's
UR = Driver("/joint_states", tuple(UR10E.robot.joints[i] for i in UR_ORDER), UR_ORDER, "actual_current",
            "/force_torque_sensor_broadcaster/wrench", "ft_raw_wrench", "tool0")
# the flange sensor's wrench as a user maps it (UR's own wrench topic is the controller's TCP estimate)
UR_MAP = '[wrench]\ntopic = "/force_torque_sensor_broadcaster/wrench"\nframe_id = "tool0"\n'
runner = CliRunner()


def ftc(*args: str) -> tuple[int, str]:
    result = runner.invoke(app, list(args))
    return result.exit_code, " ".join(result.output.split())  # rich wraps at the terminal's width


def onsets(text: str) -> int:
    return int(re.search(r"'onset': (\d+)", text).group(1))


def episodes(run) -> int:
    return int(np.sum(np.diff(run.contact.astype(int)) == 1))


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("bags")


@pytest.fixture(scope="module")
def excitation_bags(folder):
    """30 s of the planned excitation in the typical world, as two bags: a bare .mcap file, an sqlite3 folder."""
    run = run_world(UR10E, WORLD, "excitation", 30.0, seed=1)
    half = len(run.columns["timestamp"]) // 2
    out = []
    for part, storage in ((slice(0, half), "mcap"), (slice(half, None), "sqlite3")):
        path = folder / f"excitation-{storage}"
        bad = write_bag(path, {k: v[part] for k, v in run.columns.items()}, UR, storage=storage)
        out.append((storage_file(path) if storage == "mcap" else path, bad))
    return out


@pytest.fixture(scope="module")
def identified(folder, excitation_bags):
    out = folder / "cal.toml"
    code, text = ftc("identify", *(str(p) for p, _ in excitation_bags), "--scene", "ur10e", "--sensing", "currents",
                     "--out", str(out), "--no-plot")
    return code, text, out


def test_ftc_identify_takes_ur_driver_bags_counts_their_bad_messages_and_finds_the_drawn_arm(excitation_bags,
                                                                                            identified):
    code, text, out = identified
    assert code in (0, 4), text[-3000:]  # 4: poorly excited (some inertial parameter untold)
    for (path, bad), storage in zip(excitation_bags, ("mcap", "sqlite3"), strict=True):
        said = text.split(f"{path.name}: ROS 2 bag ({storage})", 1)[1][:700]
        skipped = said.split("skipped: ", 1)[1].split(")", 1)[0]
        for key, n in bad.items():
            if key.startswith("joints:"):
                assert f"{n} {key.split(':')[1].replace('_', ' ')}" in skipped, said
        assert "not used: /force_torque_sensor_broadcaster/wrench" in said, said
    kt = load_calibration(out, scene=UR10E).identification.joints["torque_constant"]
    true_kt = WORLD.world.torque_constant if WORLD.world.torque_constant is not None else UR10E.robot.torque_constant
    err = np.abs(kt - true_kt) / true_kt
    assert np.all(err[:4] < 0.05), (kt, true_kt)  # the wrists load their motors little (as from UR's CSV)


def test_ftc_replay_of_ur_driver_bags_one_onset_per_contact_none_when_free(folder, identified):
    _, _, cal = identified
    assert cal.is_file()
    (folder / "ur.toml").write_text(UR_MAP)
    hit = run_world(UR10E, WORLD, "sweep-with-collision", 10.0, seed=4)
    free = run_world(UR10E, WORLD, "sweep", 8.0, seed=4)
    assert episodes(hit) >= 1 and episodes(free) == 0
    write_bag(folder / "hit", hit.columns, UR, storage="mcap")
    bad = write_bag(folder / "free", free.columns, UR, storage="sqlite3")
    events = folder / "events.jsonl"
    code, text = ftc("replay", str(folder / "hit"), "--scene", "ur10e", "--topics", str(folder / "ur.toml"),
                     "--calibration", str(cal), "--view", "none", "--events", str(events))
    assert code == 0, text[-3000:]
    assert "sensing used: flange_ft + currents" in text and onsets(text) == episodes(hit), text[-2000:]
    assert events.read_text().count('"onset"') == episodes(hit)
    code, text = ftc("replay", str(folder / "free"), "--scene", "ur10e", "--topics", str(folder / "ur.toml"),
                     "--calibration", str(cal), "--view", "none")
    assert code == 0 and onsets(text) == 0, text[-2000:]
    wrench = text.split("wrench /force_torque_sensor_broadcaster/wrench:", 1)[1].split(")", 1)[0]
    for key, n in bad.items():
        if key.startswith("wrench:"):
            assert f"{n} {key.split(':')[1].replace('_', ' ')}" in wrench, wrench


def test_ftc_replay_of_a_franka_ros2_bag_with_its_names_and_measured_torques(folder):
    fr3 = load_scene("fr3")
    hit = run_world(fr3, fr3, "sweep-with-collision", 10.0, seed=4)
    assert "joint_torques" in hit.columns and episodes(hit) >= 1
    names = tuple(f"fr3_{j}" for j in fr3.robot.joints)
    write_bag(folder / "franka", hit.columns, Driver("/franka/joint_states", names, tuple(range(7)), "joint_torques"),
              storage="mcap")
    code, text = ftc("replay", str(folder / "franka"), "--scene", "fr3", "--view", "none")
    assert code == 0, text[-3000:]
    assert "franka_ros2's defaults (fr3)" in text and "sensing used: joint_torques" in text, text[-2000:]
    assert onsets(text) == episodes(hit), text[-2000:]


def test_ftc_replay_of_a_net_ft_bag_under_a_ur5e_is_driven_by_the_wrench(folder):
    ur5e = load_scene("ur5e")
    hit = run_world(ur5e, ur5e, "sweep-with-collision", 8.0, seed=2)
    assert episodes(hit) >= 1
    driver = Driver("/joint_states", UR.names, UR_ORDER, "actual_current", "/force_torque_sensor_broadcaster/wrench",
                    "base_ft_wrench", "tool0")
    write_bag(folder / "netft", hit.columns, driver, storage="sqlite3")
    code, text = ftc("replay", str(folder / "netft"), "--scene", "ur5e", "--view", "none")
    assert code == 0, text[-3000:]
    assert "ros2_net_ft_driver's wrench" in text and "sensing used: base_ft + currents" in text, text[-2000:]
    assert onsets(text) == episodes(hit), text[-2000:]


# -- bags and maps that cannot be used: a typed error naming what is wrong, never a crash ------------------------

@pytest.fixture(scope="module")
def small_bag(folder):
    run = run_world(UR10E, UR10E, "hold", 0.4, seed=0)
    write_bag(folder / "small", run.columns, UR, storage="mcap", bad=False)
    return folder / "small"


def test_a_bag_is_told_by_its_form(folder, small_bag):
    assert is_ros_bag(small_bag) and is_ros_bag(storage_file(small_bag))
    plain = folder / "plain.mcap"
    plain.write_bytes(b"\x89MCAP0\r\n\x01" + (13).to_bytes(8, "little") + (0).to_bytes(4, "little") + b"\0" * 9)
    assert not is_ros_bag(plain)  # an MCAP of ftc monitor: no ros2 profile
    assert not is_ros_bag(folder)  # a folder without metadata.yaml


@pytest.mark.parametrize("text, says", [
    ('[joint_states]\ntopic = "/js"\n[joint_states.names]\na = "shoulder_pan_joint"\n', "missing: shoulder_lift_joint"),
    ('[joint_states]\neffort = "amps"\n', "effort 'amps'"),
    ('[wrench]\ntopic = "/w"\n', "'frame_id' must be"),
    ('[topics]\n', "unknown table 'topics'"),
    ("not = toml = here", "not TOML"),
])
def test_a_bad_topic_map_names_its_fault(tmp_path, text, says):
    path = tmp_path / "map.toml"
    path.write_text(text)
    with pytest.raises(TopicMapError, match=re.escape(says)):
        load_topic_map(path, UR10E)


def test_a_bag_without_the_mapped_topics_or_names_or_types_is_refused_by_name(tmp_path, small_bag):
    js = default_map(UR10E).joint_states
    other = default_map(UR10E).__class__(js.__class__("/nothing", "current", js.names), None, "test")
    with pytest.raises(BagError, match="no topic /nothing.*the bag has /joint_states"):
        read_bag(small_bag, other, UR10E)
    typed = other.__class__(js.__class__("/force_torque_sensor_broadcaster/wrench", "current", js.names), None, "t")
    with pytest.raises(BagError, match="carries geometry_msgs/msg/WrenchStamped, not sensor_msgs/msg/JointState"):
        read_bag(small_bag, typed, UR10E)
    fr3 = load_scene("fr3")
    franka = default_map(fr3).joint_states
    renamed = other.__class__(js.__class__("/joint_states", "torque", franka.names), None, "t")
    with pytest.raises(BagError, match="name .*shoulder_pan_joint.*not the map's fr3_joint1"):
        read_bag(small_bag, renamed, fr3)
    (tmp_path / "frame.toml").write_text('[wrench]\ntopic = "/force_torque_sensor_broadcaster/wrench"\n'
                                         'frame_id = "ft_sensor"\n')
    with pytest.raises(BagError, match="in frame 'tool0', the map says 'ft_sensor'"):
        read_bag(small_bag, load_topic_map(tmp_path / "frame.toml", UR10E), UR10E)
    junk = tmp_path / "junk.db3"
    junk.write_bytes(b"SQLite format 3\x00" + b"\xff" * 200)
    with pytest.raises(BagError, match="cannot open as a ROS 2 bag"):
        read_bag(junk, default_map(UR10E), UR10E)


def test_a_truncated_bag_is_read_up_to_where_it_breaks(tmp_path, small_bag):
    whole = read_bag(storage_file(small_bag), default_map(UR10E), UR10E)
    cut = tmp_path / "cut.mcap"
    data = storage_file(small_bag).read_bytes()
    cut.write_bytes(data[: len(data) * 2 // 3])  # what a recorder killed leaves: no summary, no footer
    part = read_bag(cut, default_map(UR10E), UR10E)
    assert not part.complete and "cut short" in part.summary()
    assert 0.4 * len(whole.joints.t_ns) < len(part.joints.t_ns) < len(whole.joints.t_ns)
    np.testing.assert_array_equal(part.joints.values["q"], whole.joints.values["q"][: len(part.joints.t_ns)])


def test_a_cut_bag_with_compressed_chunks_keeps_its_whole_chunks_and_says_what_was_lost(tmp_path):
    """rosbag2's MCAP plugin may compress its chunks (zstd): a cut chunk cannot be read, the ones before it can."""
    from mcap.writer import CompressionType, Writer  # lazy: this test alone writes MCAP by hand

    from tests.app.ros.world_bag import JOINT_STATE, STORE, _joint_state

    path, n, names = tmp_path / "zstd.mcap", 600, list(UR.names)
    with open(path, "wb") as f:
        writer = Writer(f, chunk_size=4096, compression=CompressionType.ZSTD)
        writer.start(profile="ros2", library="test")
        msgdef = STORE.generate_msgdef(JOINT_STATE)[0]
        schema = writer.register_schema(JOINT_STATE, "ros2msg", msgdef.encode())
        channel = writer.register_channel("/joint_states", "cdr", schema)
        for i in range(n):
            t = 1_000_000_000 + 2_000_000 * i
            writer.add_message(channel, t, _joint_state(t, names, np.full(6, i * 1e-3), np.zeros(6), np.zeros(6)), t)
        writer.finish()
    whole = read_bag(path, default_map(UR10E), UR10E)
    assert whole.complete and len(whole.joints.t_ns) == n
    data, at, chunks = path.read_bytes(), 8, []
    while data[at] != 0x02:  # up to the data end record: where each chunk starts and ends
        end = at + 9 + int.from_bytes(data[at + 1:at + 9], "little")
        chunks += [(at, end)] if data[at] == 0x06 else []
        at = end
    start, end = chunks[len(chunks) // 2]
    (tmp_path / "cut.mcap").write_bytes(data[: (start + end) // 2])  # cut inside a chunk
    part = read_bag(tmp_path / "cut.mcap", default_map(UR10E), UR10E)
    assert not part.complete and "zstd-compressed chunk" in part.error and "messages are lost" in part.error
    assert 0 < len(part.joints.t_ns) < n
    np.testing.assert_array_equal(part.joints.values["q"], whole.joints.values["q"][: len(part.joints.t_ns)])
