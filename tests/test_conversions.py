"""nodes/conversions: round trips and the ValueErrors for bad messages."""
from __future__ import annotations

import math

import numpy as np
import pytest
from clothfold_msgs.msg import Keypoints
from geometry_msgs.msg import Point

from clothfold_ros.nodes import conversions as rc
from clothfold_ros.folding import fold_spec
from clothfold_ros.garment import make_shirt
from clothfold_ros.pose import Pose


@pytest.fixture(scope="module")
def shirt():
    return make_shirt(1, max_area=5e-3)


def test_time_round_trip_and_errors():
    for ns in (0, 1, 999_999_999, 1_000_000_000, 123_456_789_012):
        assert rc.time_to_ns(rc.ns_to_time(ns)) == ns
    assert rc.seconds_to_ns(0.04) == 40_000_000
    with pytest.raises(ValueError):
        rc.ns_to_time(-1)
    with pytest.raises(ValueError):
        rc.seconds_to_ns(math.nan)


def test_pose_round_trip_and_nan():
    p = Pose(np.array([0.1, -0.2, 0.3]), np.array([0.0, 0.0, math.sin(0.3), math.cos(0.3)]))
    q = rc.pose_from_msg(rc.pose_to_msg(p))
    np.testing.assert_array_equal(q.position, p.position)
    np.testing.assert_allclose(q.quaternion, p.quaternion, atol=1e-15)
    m = rc.pose_to_msg(p)
    m.position.y = math.nan
    with pytest.raises(ValueError, match="not finite"):
        rc.pose_from_msg(m)
    m = rc.pose_to_msg(p)
    m.orientation.x = m.orientation.y = m.orientation.z = m.orientation.w = 0.0
    with pytest.raises(ValueError, match="zero quaternion"):
        rc.pose_from_msg(m)


def test_keypoints_round_trip_and_errors(shirt):
    kp = shirt.keypoints()
    got, ids = rc.keypoints_from_msg(rc.keypoints_to_msg(kp, 5, shirt.keypoint_ids))
    assert list(got) == list(kp) and ids == shirt.keypoint_ids
    for n in kp:
        np.testing.assert_array_equal(got[n], kp[n])
    with pytest.raises(ValueError, match="no keypoints"):
        rc.keypoints_from_msg(Keypoints())
    with pytest.raises(ValueError, match="2 names but 1 points"):
        rc.keypoints_from_msg(Keypoints(names=["a", "b"], points=[Point()]))
    with pytest.raises(ValueError, match="duplicate"):
        rc.keypoints_from_msg(Keypoints(names=["a", "a"], points=[Point(), Point()]))
    with pytest.raises(ValueError, match="not finite"):
        rc.keypoints_from_msg(Keypoints(names=["a"], points=[Point(x=math.inf)]))


def test_fold_spec_round_trip_and_errors(shirt):
    for name in ("left_sleeve", "middle"):
        spec = fold_spec(name, shirt.keypoints())
        done = ("left_sleeve", "right_sleeve") if name == "middle" else ()
        plan = rc.PlannedFold(spec, 0.6, 25.0, 4.0, 0.2, 3, 1234, folds_done=done)
        back = rc.fold_spec_from_msg(rc.fold_spec_to_msg(plan))
        assert (back.height_ratio, back.tilt_deg, back.duration, back.settle_time, back.stage, back.stamp_ns) == \
            (0.6, 25.0, 4.0, 0.2, 3, 1234)
        assert back.spec.name == name and back.spec.n_grippers == spec.n_grippers
        assert back.folds_done == done and back.spec.tilt_signs == spec.tilt_signs
        assert back.spec.layer_offset_factor == spec.layer_offset_factor
        np.testing.assert_allclose(back.spec.line_point, spec.line_point)
        np.testing.assert_allclose(back.spec.line_direction, spec.line_direction)
        np.testing.assert_allclose(back.spec.normal, spec.normal)
        assert len(back.spec.start_poses) == len(spec.start_poses) == len(back.spec.end_poses)
        for a, b in zip(back.spec.start_poses + back.spec.end_poses, spec.start_poses + spec.end_poses):
            np.testing.assert_allclose(a.position, b.position)  # the grasps and where they are put down
            np.testing.assert_allclose(abs(a.quaternion @ b.quaternion), 1.0, atol=1e-12)  # the same rotation
    msg = rc.fold_spec_to_msg(rc.PlannedFold(fold_spec("left_sleeve", shirt.keypoints()), 0.6, 25.0, 4.0, 0.2))
    msg.duration = math.nan
    with pytest.raises(ValueError, match="duration"):
        rc.fold_spec_from_msg(msg)
    msg.duration, msg.header.frame_id = 4.0, "map"
    with pytest.raises(ValueError, match="frame"):
        rc.fold_spec_from_msg(msg)
    msg.header.frame_id, msg.tilt_signs = "table", [1.0, 1.0]
    with pytest.raises(ValueError, match="counts differ"):
        rc.fold_spec_from_msg(msg)


def test_fold_histories_round_trip_and_errors(shirt):
    """The folds a plan assumes made (FoldSpec.folds_done) and the folds keypoints follow
    (Keypoints.folds): None = not given, [] = the flat shirt; bad lists are refused."""
    spec = fold_spec("left_side", shirt.keypoints())
    for done in (None, (), ("left_sleeve", "right_sleeve")):
        back = rc.fold_spec_from_msg(rc.fold_spec_to_msg(rc.PlannedFold(spec, 0.6, 25.0, folds_done=done)))
        assert back.folds_done == done
        kp = rc.keypoints_to_msg(shirt.keypoints(), 5, folds=done)
        assert rc.keypoint_folds_from_msg(kp) == (None if done is None else list(done))
    for bad, words in ((["left_sleeve", "left_sleeve"], "twice"), (["fold_x"], "unknown folds"),
                       (["left_side"], "lists itself")):
        msg = rc.fold_spec_to_msg(rc.PlannedFold(spec, 0.6, 25.0))
        msg.folds_known, msg.folds_done = True, bad
        with pytest.raises(ValueError, match=words):
            rc.fold_spec_from_msg(msg)
    msg = rc.keypoints_to_msg(shirt.keypoints(), 5)
    msg.folds = ["left_sleeve"]  # listed, but folds_known is false
    with pytest.raises(ValueError, match="folds_known is false"):
        rc.keypoint_folds_from_msg(msg)


def test_cloth_state_round_trip_and_errors(shirt):
    v, tri = shirt.vertices + 0.001, shirt.triangles
    m = rc.cloth_state_to_msg(v, tri, shirt.keypoint_ids, 3e-4, 7, grasped=[1, 2])
    s = rc.cloth_state_from_msg(m)
    np.testing.assert_allclose(s.vertices, v, atol=1e-6)  # float32 on the wire
    np.testing.assert_array_equal(s.triangles, tri)
    assert s.keypoint_ids == shirt.keypoint_ids and s.stamp_ns == 7 and s.grasped_vertex_ids.tolist() == [1, 2]
    bad = rc.cloth_state_to_msg(v, tri, shirt.keypoint_ids, 3e-4, 7)
    bad.triangles = np.append(np.asarray(bad.triangles), [0, 1, len(v)]).astype(np.uint32)
    with pytest.raises(ValueError, match="out of range"):
        rc.cloth_state_from_msg(bad)
    bad = rc.cloth_state_to_msg(v, tri, shirt.keypoint_ids, 3e-4, 7)
    bad.keypoint_vertex_ids = np.asarray(bad.keypoint_vertex_ids)[:-1]
    with pytest.raises(ValueError, match="keypoint"):
        rc.cloth_state_from_msg(bad)
    bad = rc.cloth_state_to_msg(v, tri, shirt.keypoint_ids, 3e-4, 7)
    names = list(bad.keypoint_names)
    bad.keypoint_names = names[:-1] + names[:1]  # a name twice: never collapsed into one
    with pytest.raises(ValueError, match="duplicate keypoint names"):
        rc.cloth_state_from_msg(bad)


def test_display_messages(shirt):
    marker = rc.mesh_marker(shirt.vertices, shirt.triangles, 3)
    assert marker.type == marker.TRIANGLE_LIST and len(marker.points) == 3 * len(shirt.triangles)
    cloud = rc.mesh_points(shirt.vertices, 3)
    assert cloud.width == len(shirt.vertices) and len(cloud.data) == 12 * len(shirt.vertices)
    np.testing.assert_allclose(np.frombuffer(bytes(cloud.data), np.float32).reshape(-1, 3), shirt.vertices,
                               atol=1e-6)
    path = rc.path_msg([1, 2], [Pose(np.zeros(3), np.array([0, 0, 0, 1.0]))] * 2)
    assert len(path.poses) == 2 and path.header.frame_id == "table"
    with pytest.raises(ValueError):
        rc.gripper_command(0, -0.1, -1.0, 0)
