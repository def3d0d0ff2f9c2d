"""Bag core: definitions, QoS, writer layout, read-back with the independent `rosbags` decoder."""
from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.rosbag2.metadata import parse_qos as rosbags_parse_qos

from rosbags_decode import rosbags_messages

from clothfold_ros.bag import BagError, BagReader, BagWriter, Qos, dump_qos, message_definition, parse_qos
from clothfold_ros.bag.definitions import SEPARATOR
from clothfold_ros.bag.playback import PlaybackClock

T0 = 1_700_000_000_000_000_000  # ns


def _messages():
    """(topic, type, rclpy message) for a mix of pipeline types, deterministic values."""
    from builtin_interfaces.msg import Time
    from clothfold_msgs.msg import ClothState, FoldSpec, Keypoints
    from geometry_msgs.msg import Point, Pose, PoseStamped, Vector3
    from nav_msgs.msg import Path as PathMsg
    from sensor_msgs.msg import PointCloud2, PointField
    from std_msgs.msg import Float64MultiArray, String
    from visualization_msgs.msg import Marker

    rng = np.random.default_rng(7)
    out = []
    for i in range(30):
        p = PoseStamped()
        p.header.stamp = Time(sec=100 + i, nanosec=5 * i)
        p.header.frame_id = "table"
        p.pose.position.x, p.pose.position.y, p.pose.position.z = (float(v) for v in rng.normal(size=3))
        p.pose.orientation.w = 1.0
        out.append(("/gripper_0/target_pose", "geometry_msgs/msg/PoseStamped", p))
    path = PathMsg()
    path.header.frame_id = "table"
    for i in range(5):
        ps = PoseStamped()
        ps.pose.position.x = 0.1 * i
        path.poses.append(ps)
    out.append(("/gripper_0/path", "nav_msgs/msg/Path", path))
    mk = Marker(ns="cloth", id=3, type=Marker.TRIANGLE_LIST, action=Marker.ADD)
    mk.points = [Point(x=float(i), y=-float(i), z=0.5) for i in range(6)]
    mk.scale = Vector3(x=1.0, y=1.0, z=1.0)
    out.append(("/cloth/marker", "visualization_msgs/msg/Marker", mk))
    pts = rng.normal(size=(40, 3)).astype(np.float32)
    pc = PointCloud2(height=1, width=40, is_bigendian=False, point_step=12, row_step=480, is_dense=True)
    pc.fields = [PointField(name=n, offset=4 * k, datatype=PointField.FLOAT32, count=1) for k, n in enumerate("xyz")]
    pc.data = pts.tobytes()
    out.append(("/cloth/points", "sensor_msgs/msg/PointCloud2", pc))
    kp = Keypoints(names=["bottom_right", "neck_middle"], points=[Point(x=0.3, y=-0.2), Point(y=0.35)],
                   vertex_ids=[12, -1])
    out.append(("/keypoints", "clothfold_msgs/msg/Keypoints", kp))
    fs = FoldSpec(fold_name="left_sleeve", stage=2, line_point=Point(x=0.1), line_direction=Vector3(y=1.0),
                  start_poses=[Pose(position=Point(x=0.2, z=0.01))], end_poses=[Pose(position=Point(x=-0.2))],
                  tilt_signs=[1.0], height_ratio=0.45, tilt_deg=51.4, duration=4.0, settle_time=0.2,
                  layer_offset_factor=2.0)
    out.append(("/fold/spec", "clothfold_msgs/msg/FoldSpec", fs))
    cs = ClothState(positions=rng.normal(size=30).astype(np.float32).tolist(), triangles=list(range(9)),
                    keypoint_names=["a"], keypoint_vertex_ids=[4], thickness=0.001, grasped_vertex_ids=[1, 2])
    out.append(("/cloth/state", "clothfold_msgs/msg/ClothState", cs))
    out.append(("/note", "std_msgs/msg/String", String(data="héllo")))
    out.append(("/arr", "std_msgs/msg/Float64MultiArray", Float64MultiArray(data=[1.5, -2.0])))
    return out


LATCHED = Qos(depth=1, durability="transient_local")


def _write(path: Path, chunk_size: int = 1500) -> list[tuple[str, str, object, int, bytes]]:
    """(topic, type, message, log time ns, the bytes written) per message. The bytes are kept:
    rclpy's CDR serialization leaves alignment padding uninitialised, so serializing the same
    message again may give other padding bytes (seen: b"pd\x1ep" where the bag holds zeros)."""
    written = []
    with BagWriter(path, chunk_size=chunk_size) as w:
        for k, (topic, typ, msg) in enumerate(_messages()):
            qos = [LATCHED] if topic in ("/keypoints", "/fold/spec") else [Qos(depth=1000), Qos(depth=5)]
            w.add_topic(topic, typ, qos)
            t = T0 + 10_000_000 * k
            data = serialize_message(msg)
            w.write(topic, data, t, t - 1000)
            written.append((topic, typ, msg, t, data))
    return written


def _ros_value(v):
    """Comparable value of an rclpy message field (recursive)."""
    if hasattr(v, "get_fields_and_field_types"):
        return {f: _ros_value(getattr(v, f)) for f in v.get_fields_and_field_types()}
    if isinstance(v, (list, tuple)) or hasattr(v, "tolist"):
        return [_ros_value(x) for x in (v.tolist() if hasattr(v, "tolist") else v)]
    if isinstance(v, (bytes, bytearray)):
        return list(v)
    return v


def _rb_value(v):
    """Comparable value of a rosbags-decoded message (recursive)."""
    if dataclasses.is_dataclass(v):  # constants (UPPER_CASE) are not fields of the rclpy message
        return {f.name: _rb_value(getattr(v, f.name)) for f in dataclasses.fields(v)
                if f.name != "__msgtype__" and not f.name.isupper()}
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, (list, tuple)):
        return [_rb_value(x) for x in v]
    return v


def _decode_all_with_rosbags(path: Path):
    """Every message of a single .mcap decoded by rosbags (empty type store), as plain values."""
    return [(topic, t, _rb_value(msg)) for topic, t, msg in rosbags_messages(path)]


def test_definition_layout_matches_rosbag2():
    d = message_definition("nav_msgs/msg/Path")
    blocks = d.text.split("\n" + SEPARATOR + "\n")
    heads = [b.splitlines()[0] for b in blocks[1:]]
    assert heads == ["MSG: std_msgs/Header", "MSG: builtin_interfaces/Time", "MSG: geometry_msgs/PoseStamped",
                     "MSG: geometry_msgs/Pose", "MSG: geometry_msgs/Point", "MSG: geometry_msgs/Quaternion"]
    assert "/msg/" not in "".join(heads)
    assert len(SEPARATOR) == 80 and set(SEPARATOR) == {"="}
    share = Path(os.environ["AMENT_PREFIX_PATH"].split(":")[-1]) / "share"
    assert blocks[0] == (share / "nav_msgs/msg/Path.msg").read_text().rstrip("\n")
    desc = json.loads((share / "nav_msgs/msg/Path.json").read_text())
    assert d.type_hash == desc["type_hashes"][0]["hash_string"]
    assert d.type_hash.startswith("RIHS01_") and len(d.type_hash) == 7 + 64
    assert message_definition("nav_msgs/Path") == d


def test_definition_errors_are_clear():
    with pytest.raises(BagError, match="no nosuch_msgs/msg/Thing.msg"):
        message_definition("nosuch_msgs/msg/Thing")
    with pytest.raises(BagError, match="bad ROS type name"):
        message_definition("justaname")


def test_qos_yaml_roundtrip_and_rosbags_agrees():
    offers = [Qos(depth=1, durability="transient_local"), Qos(history="unknown", depth=0, reliability="best_effort",
                                                             deadline_ns=1_500_000_000)]
    text = dump_qos(offers)
    assert parse_qos(text) == offers
    items = yaml.safe_load(text)
    assert all(list(i) == ["history", "depth", "reliability", "durability", "deadline", "lifespan", "liveliness",
                           "liveliness_lease_duration", "avoid_ros_namespace_conventions"] for i in items)
    assert items[0]["lifespan"] == {"sec": 9223372036, "nsec": 854775807}
    theirs = rosbags_parse_qos(text)
    assert [q.durability.name.lower() for q in theirs] == ["transient_local", "volatile"]
    assert [q.reliability.name.lower() for q in theirs] == ["reliable", "best_effort"]
    assert (theirs[1].deadline.sec, theirs[1].deadline.nsec) == (1, 500_000_000)
    with pytest.raises(BagError):
        parse_qos("- history: sometimes\n  depth: 1")
    with pytest.raises(BagError):
        Qos(durability="sticky")


def test_rosbags_decodes_every_message_with_empty_typestore(tmp_path):
    path = tmp_path / "mix.mcap"
    written = _write(path)
    decoded = _decode_all_with_rosbags(path)
    assert len(decoded) == len(written)
    by_time = {t: (topic, v) for topic, t, v in decoded}
    for topic, _, msg, t, _ in written:
        got_topic, got = by_time[t]
        assert got_topic == topic
        assert got == _ros_value(msg), topic


def test_mcap_layout_schema_qos_hash_metadata(tmp_path):
    path = tmp_path / "mix.mcap"
    written = _write(path, chunk_size=800)
    with open(path, "rb") as f:
        r = make_reader(f)
        assert r.get_header().profile == "ros2"
        s = r.get_summary()
        assert s.statistics.message_count == len(written)
        assert s.statistics.chunk_count > 3
        assert len(s.chunk_indexes) == s.statistics.chunk_count
        for ch in s.channels.values():
            schema = s.schemas[ch.schema_id]
            assert ch.message_encoding == "cdr" and schema.encoding == "ros2msg"
            assert schema.data.decode() == message_definition(schema.name).text
            assert ch.metadata["topic_type_hash"] == message_definition(schema.name).type_hash
            offers = yaml.safe_load(ch.metadata["offered_qos_profiles"])
            want = "transient_local" if ch.topic in ("/keypoints", "/fold/spec") else "volatile"
            assert [o["durability"] for o in offers][0] == want
        meta = {m.name: m.metadata for m in r.iter_metadata()}
        info = yaml.safe_load(meta["rosbag2"]["serialized_metadata"])  # the bare map, as rosbag2 writes and reads it
    assert info["version"] == 9 and info["storage_identifier"] == "mcap"
    assert info["message_count"] == len(written)
    assert info["starting_time"]["nanoseconds_since_epoch"] == written[0][3]
    assert info["duration"]["nanoseconds"] == written[-1][3] - written[0][3]
    counts = {t["topic_metadata"]["name"]: t["message_count"] for t in info["topics_with_message_count"]}
    assert counts["/gripper_0/target_pose"] == 30 and sum(counts.values()) == len(written)


def test_bag_directory_with_metadata_yaml_opens_in_rosbags_reader(tmp_path):
    bagdir = tmp_path / "run1"
    written = _write(bagdir)
    assert (bagdir / "metadata.yaml").is_file() and (bagdir / "run1_0.mcap").is_file()
    with RosbagsReader(bagdir) as r:
        assert r.message_count == len(written)
        latched = [c for c in r.connections if c.topic == "/keypoints"][0]
        assert latched.ext.offered_qos_profiles[0].durability.name == "TRANSIENT_LOCAL"
        assert latched.digest == message_definition("clothfold_msgs/msg/Keypoints").type_hash
        assert sorted(c.topic for c in r.connections) == sorted({w[0] for w in written})
    with BagReader(bagdir) as b:
        assert b.message_count == len(written)


def test_own_reader_time_order_filter_and_bytes(tmp_path):
    path = tmp_path / "mix.mcap"
    written = _write(path)
    with BagReader(path) as b:
        msgs = list(b.messages())
        assert [m.log_time_ns for m in msgs] == sorted(w[3] for w in written)
        assert [m.data for m in msgs] == [w[4] for w in written]
        assert all(m.publish_time_ns == m.log_time_ns - 1000 for m in msgs)
        poses = list(b.messages(topics=["/gripper_0/target_pose"], start_ns=T0 + 10_000_000 * 10))
        assert len(poses) == 20
        assert b.topics["/keypoints"].offered_qos == [LATCHED]
        assert b.duration_ns == written[-1][3] - T0
        with pytest.raises(BagError, match="no topic /nope"):
            list(b.messages(topics=["/nope"]))


def test_writer_rejects_bad_input(tmp_path):
    path = tmp_path / "x.mcap"
    with BagWriter(path) as w:
        w.add_topic("/a", "std_msgs/msg/String")
        with pytest.raises(BagError, match="not added"):
            w.write("/b", b"", T0)
        with pytest.raises(BagError, match="already recorded as"):
            w.add_topic("/a", "std_msgs/msg/Int32")
        with pytest.raises(BagError, match="absolute"):
            w.add_topic("a", "std_msgs/msg/String")
    with pytest.raises(BagError, match="exists"):
        BagWriter(path)
    with pytest.raises(BagError, match="closed"):
        w.write("/a", b"", T0)
    with BagWriter(path, overwrite=True) as w2:  # what the recorder (and `launch --record --force`) does
        w2.add_topic("/b", "std_msgs/msg/String")
        w2.write("/b", b"\x00\x01\x00\x00\x01\x00\x00\x00\x00", T0)
    with BagReader(path) as b:
        assert list(b.topics) == ["/b"] and b.message_count == 1  # the old bag replaced, not appended to


@pytest.mark.parametrize("bad", [
    dict(log_time_ns=-1), dict(log_time_ns=2**63), dict(log_time_ns=T0, publish_time_ns=-1),
    dict(log_time_ns=T0, publish_time_ns=2**64), dict(log_time_ns=float(T0)), dict(log_time_ns=True),
    dict(log_time_ns=T0, publish_time_ns=1.5), dict(log_time_ns="5"),
])
def test_writer_refuses_bad_times_and_stays_usable(tmp_path, bad):
    """A time MCAP cannot store (not an int in [0, 2**63): uint64 for MCAP, signed for ROS 2) is refused with BagError before it
    reaches the file: the messages before and after it are read back by this package's reader,
    by mcap's and by rosbags, and the summary counts only them."""
    from std_msgs.msg import String

    path = tmp_path / "t.mcap"
    first, second = serialize_message(String(data="before")), serialize_message(String(data="after"))
    with BagWriter(path) as w:
        w.add_topic("/s", "std_msgs/msg/String")
        w.write("/s", first, T0, T0 - 7)
        with pytest.raises(BagError, match=r"time .*on /s"):
            w.write("/s", serialize_message(String(data="bad")), **bad)
        w.write("/s", second, T0 + 1000)
    assert w.message_count == 2
    with BagReader(path) as b:
        got = [(m.log_time_ns, m.publish_time_ns, m.data) for m in b.messages()]
        assert b.message_count == 2
    assert got == [(T0, T0 - 7, first), (T0 + 1000, T0 + 1000, second)]
    with open(path, "rb") as f:
        r = make_reader(f)
        assert r.get_summary().statistics.message_count == 2
        assert [(m.log_time, m.publish_time, m.sequence, m.data) for _, _, m in r.iter_messages()] == [
            (T0, T0 - 7, 1, first), (T0 + 1000, T0 + 1000, 2, second)]
    assert [(t, ts, _rb_value(m)) for t, ts, m in rosbags_messages(path)] == [
        ("/s", T0, {"data": "before"}), ("/s", T0 + 1000, {"data": "after"})]


def test_writer_takes_numpy_integer_times(tmp_path):
    path = tmp_path / "n.mcap"
    with BagWriter(path) as w:
        w.add_topic("/s", "std_msgs/msg/String", definition="string data", type_hash="h")
        w.write("/s", b"\x00\x01\x00\x00\x01\x00\x00\x00\x00\x00\x00\x00", np.int64(T0), np.uint64(2**63 - 1))
    with BagReader(path) as b:
        assert [(m.log_time_ns, m.publish_time_ns) for m in b.messages()] == [(T0, 2**63 - 1)]


def test_playback_clock_rate():
    c = PlaybackClock(bag_start_ns=T0, wall_start=10.0, rate=2.0)
    assert c.due(T0 + 3_000_000_000) == pytest.approx(11.5)
    assert c.bag_time_ns(11.5) == T0 + 3_000_000_000
    with pytest.raises(ValueError):
        PlaybackClock(T0, 0.0, rate=0.0)


def test_player_refuses_non_finite_settings():
    """argparse takes 'nan' and 'inf' for floats: the player refuses them with the option's name."""
    import math

    from clothfold_ros.bag import BagError
    from clothfold_ros.nodes.player_node import Player

    for kwargs, words in (({"rate": math.nan}, "--rate"), ({"rate": math.inf}, "--rate"),
                          ({"start_offset": math.nan}, "--start-offset"), ({"start_offset": -1.0}, "--start-offset"),
                          ({"clock_hz": math.nan}, "--clock"), ({"clock_hz": 0.0}, "--clock")):
        with pytest.raises(BagError, match=words):
            Player(None, None, **kwargs)


def test_filter_keeps_topics_window_and_bytes_and_rosbags_reads_it(tmp_path):
    from clothfold_ros.bag import filter_bag
    from clothfold_ros.cli import main

    src = tmp_path / "mix.mcap"
    written = _write(src)
    out = tmp_path / "cut.mcap"
    window = (T0 + 10_000_000 * 10, T0 + 10_000_000 * 20)  # poses 10..19
    report = filter_bag(src, out, topics=["/gripper_0/target_pose", "/keypoints"], start_ns=window[0],
                        end_ns=window[1])
    assert report.kept == {"/gripper_0/target_pose": 10} and report.read == 10
    with BagReader(out) as b, BagReader(src) as a:
        msgs = list(b.messages())
        assert [(m.topic, m.log_time_ns, m.publish_time_ns, m.data) for m in msgs] == \
            [(m.topic, m.log_time_ns, m.publish_time_ns, m.data) for m in a.messages(["/gripper_0/target_pose"], *window)]
        info, orig = b.topics["/gripper_0/target_pose"], a.topics["/gripper_0/target_pose"]
        assert (info.type, info.definition, info.type_hash, info.offered_qos) == \
            (orig.type, orig.definition, orig.type_hash, orig.offered_qos)
    assert [m.pose.position.x for _, _, m in rosbags_messages(out)] == \
        [w[2].pose.position.x for w in written[10:20]]

    # a predicate and an exclude regex; a bag directory as output
    odd = filter_bag(src, tmp_path / "odd", exclude="^/gripper_", keep=lambda m: m.log_time_ns % 20_000_000 == 10_000_000)
    with BagReader(tmp_path / "odd") as b, BagReader(src) as a:
        kept = [(m.topic, m.log_time_ns) for m in b.messages()]
        rest = [(m.topic, m.log_time_ns) for m in a.messages() if not m.topic.startswith("/gripper_")]
        assert kept == [k for k in rest if k[1] % 20_000_000 == 10_000_000]  # the predicate's selection, exactly
        assert 0 < len(kept) < len(rest) == odd.read and b.message_count == sum(odd.kept.values())

    # refusals: unknown topic, bad regex, empty window, existing output, the source itself; none leaves a file
    for kwargs, match in (({"topics": ["/nope"]}, "no topic /nope"), ({"exclude": "("}, "bad exclude regex"),
                          ({"start_ns": T0 + 5, "end_ns": T0 + 5}, "empty time window")):
        with pytest.raises(BagError, match=match):
            filter_bag(src, tmp_path / "bad.mcap", **kwargs)
        assert not (tmp_path / "bad.mcap").exists()
    with pytest.raises(BagError, match="exists"):
        filter_bag(src, out)
    with pytest.raises(BagError, match="must lie apart from the source"):
        filter_bag(src, src, overwrite=True)
    # a bag directory and its own file, either way round: refused before anything is opened for writing
    d = tmp_path / "run1"
    _write(d)
    inner = d / "run1_0.mcap"
    before = inner.read_bytes()
    for a, b in ((inner, d), (d, inner), (d, d / "sub" / "x.mcap")):
        with pytest.raises(BagError, match="must lie apart from the source"):
            filter_bag(a, b, overwrite=True)
    assert inner.read_bytes() == before
    # a selection of no message is refused, and an output that existed stays as it was
    kept = out.read_bytes()
    with pytest.raises(BagError, match="no message selected"):
        filter_bag(src, out, topics=["/keypoints"], start_ns=T0, end_ns=T0 + 1, overwrite=True)
    with pytest.raises(BagError, match="every topic selected is excluded"):
        filter_bag(src, out, exclude=".", overwrite=True)
    assert out.read_bytes() == kept
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".filter-")] == []  # no staging left behind

    # the command: seconds after the bag's first message
    assert main(["bag", "filter", str(src), "-o", str(out), "--topics", "/gripper_0/target_pose", "--start", "0.1",
                 "--end", "0.2", "--force"]) == 0
    with BagReader(out) as b:
        assert b.message_count == 10
    assert main(["bag", "filter", str(src), "-o", str(tmp_path / "x.mcap"), "--start", "nan"]) == 1
    assert not (tmp_path / "x.mcap").exists()
