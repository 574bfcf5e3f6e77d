"""ROS 2 outputs (scattertrack.io.ros2), read back with independent readers:
``mcap`` + ``mcap-ros2-support`` for MCAP, ``rosbags`` for the bag."""

from __future__ import annotations

import numpy as np
import pytest

from scattertrack import track
from scattertrack.io import ros2
from scattertrack.sim import load_scenario, simulate


@pytest.fixture(scope="module")
def tracked():
    scenario = load_scenario("glac-3d-arm-5tags") | {"duration_s": 3.0}
    sim = simulate(scenario, seed=2)
    return sim, track.run("glac", sim.scene, sim.reads, covariance=True)


def _rows_per_tag(result):
    epcs, counts = np.unique(result.epc.astype(str), return_counts=True)
    return dict(zip(epcs.tolist(), counts.tolist()))


def test_mcap_reads_back_with_the_mcap_ros2_decoder(tracked, tmp_path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    sim, result = tracked
    counts = ros2.write_mcap(tmp_path / "track.mcap", result, sim.scene)
    got: dict = {}
    with open(tmp_path / "track.mcap", "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            got.setdefault(channel.topic, []).append((message.log_time, decoded))
    for epc, rows in _rows_per_tag(result).items():
        assert len(got[ros2.topic(epc, "pose")]) == len(got[ros2.topic(epc, "odom")]) == rows == counts[ros2.topic(epc, "pose")]
    assert len(got[ros2.ANTENNA_TOPIC]) == 1 and len(got[ros2.ANTENNA_TOPIC][0][1].markers) == 2 * len(sim.scene.antennas)
    epc = result.epc[0]
    mine = np.flatnonzero(result.epc == epc)
    for (stamp, pose), i in zip(got[ros2.topic(epc, "pose")], mine):
        p = pose.pose.pose.position
        assert np.allclose([p.x, p.y, p.z], result.position[i], atol=1e-9)
        covariance = np.array(pose.pose.covariance).reshape(6, 6)
        assert np.allclose(covariance[:3, :3], result.covariance[i][:3, :3], rtol=1e-12, atol=0)
        assert covariance[3, 3] == ros2.UNKNOWN_ROTATION_VARIANCE
        assert abs(stamp / 1e9 - result.time_s[i]) < 1e-9 and pose.header.frame_id == "scattertrack"


def test_the_ros2_bag_reads_back_with_rosbags(tracked, tmp_path):
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    sim, result = tracked
    ros2.write_ros2_bag(tmp_path / "bag", result, sim.scene, frame_id="world")
    store = get_typestore(Stores.ROS2_HUMBLE)
    per_topic: dict = {}
    with Reader(tmp_path / "bag") as reader:
        for connection, stamp, raw in reader.messages():
            per_topic.setdefault(connection.topic, []).append(store.deserialize_cdr(raw, connection.msgtype))
    for epc, rows in _rows_per_tag(result).items():
        odometry = per_topic[ros2.topic(epc, "odom")]
        assert len(odometry) == len(per_topic[ros2.topic(epc, "pose")]) == rows
        mine = np.flatnonzero(result.epc == epc)
        v = odometry[-1].twist.twist.linear
        assert np.allclose([v.x, v.y, v.z], result.velocity[mine[-1]], atol=1e-9)
        twist_covariance = np.array(odometry[-1].twist.covariance).reshape(6, 6)
        assert np.allclose(twist_covariance[:3, :3], result.covariance[mine[-1]][3:, 3:])
        assert odometry[-1].header.frame_id == "world" and odometry[-1].child_frame_id == f"tag_{epc}"


def test_a_transform_moves_positions_and_rotates_covariances(tracked, tmp_path):
    sim, result = tracked
    transform = ros2.Transform.parse("1,2,3,0.7071067811865476,0,0,0.7071067811865476")  # 90 degrees about z
    first = next(m for t, _, _, m in ros2.messages(result, None, transform=transform) if t.endswith("/pose"))
    x, y, z = result.position[np.argsort(result.time_s, kind="stable")[0]]
    p = first.pose.pose.position
    assert np.allclose([p.x, p.y, p.z], [1 - y, 2 + x, 3 + z], atol=1e-9)
    with pytest.raises(ValueError, match="seven finite numbers"):
        ros2.Transform.parse("1,2,3")
    with pytest.raises(ValueError, match="not a unit quaternion"):
        ros2.Transform.parse("0,0,0,2,0,0,0")


def test_track_writes_mcap_and_a_bag_and_refuses_an_existing_bag(tmp_path, capsys):
    from scattertrack.cli import main

    assert main(["simulate", "--scenario", "glac-2d-10cms", "--out", str(tmp_path / "s"), "--duration", "3"]) == 0
    base = ["track", "--scene", str(tmp_path / "s/scene.toml"), "--reads", str(tmp_path / "s/reads.csv"), "--out", str(tmp_path / "t.csv"), "--no-progress"]
    assert main(base + ["--mcap", str(tmp_path / "t.mcap"), "--ros2-bag", str(tmp_path / "bag"), "--transform", "0,0,1,1,0,0,0"]) == 0
    out = capsys.readouterr().out
    assert "ROS 2 messages on" in out and (tmp_path / "t.mcap").stat().st_size > 0 and (tmp_path / "bag").is_dir()
    assert main(base + ["--ros2-bag", str(tmp_path / "bag")]) == 2
    assert "already exists" in capsys.readouterr().err
    assert main(base + ["--mcap", str(tmp_path / "u.mcap"), "--transform", "1,2"]) == 2
    assert "--transform: expected" in capsys.readouterr().err


def test_one_builder_serves_a_whole_track_and_a_single_estimate(tracked):
    sim, result = tracked
    builder = ros2.Builder("map")
    whole = [(t, s, builder.cdr(m, k)) for t, k, s, m in ros2.messages(result, None, frame_id="map")]
    i = int(np.argsort(result.time_s, kind="stable")[0])
    single = builder.row(float(result.time_s[i]), str(result.epc[i]), result.position[i], result.velocity[i], covariance=result.covariance[i])
    assert [(t, s, builder.cdr(m, k)) for t, k, s, m in single] == whole[:2]
