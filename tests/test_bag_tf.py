"""Frames and grippers for Foxglove: the recorder writes /tf_static and /tf (tf2_msgs/msg/TFMessage,
not installed from the PyPI wheels) exactly as rosbag2 would for ROS 2 Jazzy, and the backends draw
each gripper as its grasp box on /gripper_<i>/marker at every step. A recorded kinematic fold is
decoded with rosbags and an empty type store (only the definitions in the bag)."""
from __future__ import annotations

import json
import math
import time
from pathlib import Path

import pytest

from pipeline_helpers import FAST_KINEMATIC, running_pipeline
from rosbags_decode import rosbags_messages

from clothfold_ros.bag import BagReader
from clothfold_ros.bag.tf import TF_TYPE, TF_TYPE_HASH, Transform, encode_tf_message, tf_definition

DOMAIN = 174


def _ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def test_tf_message_is_jazzy_cdr():
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    transforms = [Transform("world", "table", 0),
                  Transform("table", "gripper_1", 12_345_678_901, (0.1, -0.25, 0.3), (0.5, -0.5, 0.5, 0.5))]
    data = encode_tf_message(transforms)
    jazzy = get_typestore(Stores.ROS2_JAZZY)  # rosbags' own copy of the Jazzy interfaces
    t = jazzy.types
    ref = t[TF_TYPE](transforms=[t["geometry_msgs/msg/TransformStamped"](
        header=t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=x.stamp_ns // 10**9,
                                                                               nanosec=x.stamp_ns % 10**9),
                                        frame_id=x.parent),
        child_frame_id=x.child,
        transform=t["geometry_msgs/msg/Transform"](translation=t["geometry_msgs/msg/Vector3"](*x.translation),
                                                   rotation=t["geometry_msgs/msg/Quaternion"](*x.rotation)))
        for x in transforms])
    assert data == bytes(jazzy.serialize_cdr(ref, TF_TYPE))
    text, type_hash = tf_definition()
    assert text.startswith("geometry_msgs/TransformStamped[] transforms\n" + "=" * 80 + "\n"
                           "MSG: geometry_msgs/TransformStamped\n")
    headers = [ln for ln in text.splitlines() if ln.startswith("MSG: ")]
    assert "MSG: std_msgs/Header" in headers and not any("/msg/" in ln for ln in headers)  # Foxglove needs pkg/Type
    empty = get_typestore(Stores.EMPTY)
    empty.register(get_types_from_msg(text, TF_TYPE))
    back = empty.deserialize_cdr(data, TF_TYPE)
    assert [(x.header.frame_id, x.child_frame_id) for x in back.transforms] == [("world", "table"),
                                                                                 ("table", "gripper_1")]
    assert type_hash == TF_TYPE_HASH


def test_tf_type_hash_is_what_rosidl_computes(tmp_path):
    """The RIHS01 hash is recomputed by rosidl's own generator from TFMessage.msg and the installed
    geometry_msgs type description."""
    g = pytest.importorskip("rosidl_generator_type_description")
    from rosidl_adapter.msg import convert_msg_to_idl
    from rosidl_parser.definition import IdlLocator, Message
    from rosidl_parser.parser import parse_idl_file

    from clothfold_ros.bag.definitions import interface_file
    from clothfold_ros.bag.tf import TF_MSG_TEXT

    (tmp_path / "tf2_msgs" / "msg").mkdir(parents=True)
    (tmp_path / "tf2_msgs" / "msg" / "TFMessage.msg").write_text(TF_MSG_TEXT)
    idl = convert_msg_to_idl(tmp_path, "tf2_msgs", Path("tf2_msgs/msg/TFMessage.msg"), tmp_path / "idl")
    parsed = parse_idl_file(IdlLocator(tmp_path / "idl", idl.relative_to(tmp_path / "idl")))
    msg = next(e for e in parsed.content.elements if isinstance(e, Message))
    own = g.serialize_individual_type_description(msg.structure.namespaced_type, msg.structure.members)
    stamped = json.loads(interface_file("geometry_msgs", "msg", "TransformStamped", ".json").read_text())
    refs = {r["type_name"]: r for r in stamped["type_description_msg"]["referenced_type_descriptions"]}
    refs["geometry_msgs/msg/TransformStamped"] = stamped["type_description_msg"]["type_description"]
    full = {"type_description": own, "referenced_type_descriptions": [refs[k] for k in sorted(refs)]}
    assert g.calculate_type_hash(full) == TF_TYPE_HASH


def test_gripper_marker_is_the_grasp_box():
    import numpy as np
    from visualization_msgs.msg import Marker

    from clothfold_ros.nodes.backend import GRIPPER_BOX, gripper_marker
    from clothfold_ros.pose import Pose
    from clothfold_ros.sim.grasp import GRASP_BOX

    assert GRIPPER_BOX == tuple(float(v) for v in GRASP_BOX)
    pose = Pose(np.array([0.1, 0.2, 0.03]), np.array([0.0, 0.0, 0.0, 1.0]))
    closed, opened = gripper_marker(1, pose, True, 5), gripper_marker(1, pose, False, 5)
    assert closed.type == Marker.CUBE and closed.header.frame_id == "table" and closed.id == 1
    assert (closed.scale.x, closed.scale.y, closed.scale.z) == GRIPPER_BOX
    assert (closed.pose.position.x, closed.pose.position.z) == (0.1, 0.03)
    assert (closed.color.r, closed.color.g) != (opened.color.r, opened.color.g)


@pytest.fixture
def pipeline(monkeypatch):
    with running_pipeline(monkeypatch, DOMAIN, "kinematic", FAST_KINEMATIC, "test_bag_tf") as pair:
        yield pair


def test_recorded_fold_has_gripper_markers_and_frames(pipeline, tmp_path):
    from clothfold_ros.cli.launcher import node_command

    launcher, client = pipeline
    bag = tmp_path / "tf.mcap"
    rec = launcher.start("recorder_node", node_command("recorder_node", args=["--output", str(bag)]))
    launcher.wait_for(rec, r"recording to", 60)
    for topic in ("/gripper_0/pose", "/gripper_0/marker", "/gripper_0/target_pose", "/fold/result"):
        launcher.wait_for(rec, f"matched {topic} ", 30)
    client.wait_keypoints(60)
    before = client.result_count()
    resp = client.plan("left_sleeve", execute=True)
    assert resp.success, resp.message
    res = client.wait_result("left_sleeve", 60, after=before)
    assert res.success and res.steps == 50, res.reason  # 2 s / 0.04 s
    time.sleep(0.5)  # the last markers (open) reach the recorder
    assert launcher.stop(rec) == 0
    launcher.procs.remove(rec)  # stopped on purpose; the pipeline nodes must still be alive at the end
    msgs = rosbags_messages(bag)  # empty type store: decoded from the bag's own definitions
    by_topic: dict[str, list] = {}
    for topic, _, m in msgs:
        by_topic.setdefault(topic, []).append(m)
    with BagReader(bag) as b:
        tf_info = {t: b.topics[t] for t in ("/tf", "/tf_static")}
    assert all(i.type == TF_TYPE and i.type_hash == TF_TYPE_HASH for i in tf_info.values())
    assert tf_info["/tf_static"].offered_qos[0].durability == "transient_local"

    # /tf_static: the table frame under a fixed root
    static = [(t.header.frame_id, t.child_frame_id) for m in by_topic["/tf_static"] for t in m.transforms]
    assert ("world", "table") in static
    # /tf: table -> gripper_0 for every recorded gripper pose, same stamp and values
    poses = by_topic["/gripper_0/pose"]
    tfs = [t for m in by_topic["/tf"] for t in m.transforms]
    assert {(t.header.frame_id, t.child_frame_id) for t in tfs} == {("table", "gripper_0")}
    assert len(tfs) == len(poses) >= res.steps
    for p, t in zip(poses, tfs):
        assert _ns(t.header.stamp) == _ns(p.header.stamp)
        assert (t.transform.translation.x, t.transform.rotation.w) == (p.pose.position.x, p.pose.orientation.w)

    # /gripper_0/marker: the grasp box at every step (closed, red), then open (green) where it opened
    markers = by_topic["/gripper_0/marker"]
    assert all(m.type == 1 and (m.scale.x, m.scale.y, m.scale.z) == (0.05, 0.12, 0.05) for m in markers)
    assert all(m.header.frame_id == "table" for m in markers)
    closed = [m for m in markers if m.color.r > m.color.g]
    assert len(closed) >= res.steps
    assert markers[-1].color.g > markers[-1].color.r  # drawn open after the fold
    pose_at = {_ns(p.header.stamp): p.pose.position for p in poses}
    matched = [m for m in closed if _ns(m.header.stamp) in pose_at]
    assert len(matched) >= res.steps
    assert all(math.isclose(m.pose.position.y, pose_at[_ns(m.header.stamp)].y) for m in matched)
