"""The unchanged pipeline against kinematic_robot_node (separate processes), and the bad inputs
every node must survive while it keeps serving: unknown folds, NaN or missing keypoints, a new
fold while one runs, motions outside the workspace or faster than the speed limit."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest
from clothfold_msgs.msg import Keypoints
from geometry_msgs.msg import Point

from pipeline_helpers import running_pipeline

from clothfold_ros.ros_conversions import fold_spec_from_msg

DOMAIN = 151


@pytest.fixture
def pipeline(monkeypatch):
    overrides = {
        "fold_planner_node": {"selection": "parameter", "duration": 2.0},
        "kinematic_robot_node": {"real_time_factor": 4.0},
        "keypoint_node": {"model_period": 0.5},
    }
    with running_pipeline(monkeypatch, DOMAIN, "kinematic", overrides, "test_pipeline_kinematic") as pair:
        yield pair  # a node that died fails the test


def _log(launcher, name):
    return "\n".join(next(p for p in launcher.procs if p.name == name).lines)


def test_kinematic_pipeline_and_bad_inputs(pipeline):
    launcher, client = pipeline
    client.wait_keypoints(60)

    # unknown fold name
    r = client.plan("top_sleeve", execute=True)
    assert not r.success and "unknown fold" in r.message

    # a fold, and a second one while it runs: refused, the first completes
    before = client.result_count()
    r = client.plan("left_sleeve", execute=True)
    assert r.success, r.message
    r2 = client.plan("right_sleeve", execute=True)
    assert not r2.success and "refused" in r2.message
    res = client.wait_result("left_sleeve", 60, after=before)
    assert res.success and math.isnan(res.loss) and res.steps == 50  # 2 s / 0.04 s
    assert "still running" in _log(launcher, "trajectory_node")

    # goals straight to trajectory_node: too fast, outside the workspace, NaN
    good = client.plan("right_sleeve", execute=False).spec
    fast = fold_spec_from_msg(good)
    fast_msg = type(good)(**{k: getattr(good, k) for k in good.get_fields_and_field_types()})
    fast_msg.duration = 0.3
    assert not client.send_goal(fast_msg)
    far = type(good)(**{k: getattr(good, k) for k in good.get_fields_and_field_types()})
    far.end_poses[0].position.x = 5.0
    assert not client.send_goal(far)
    nan = type(good)(**{k: getattr(good, k) for k in good.get_fields_and_field_types()})
    nan.tilt_deg = math.nan
    assert not client.send_goal(nan)
    log = _log(launcher, "trajectory_node")
    assert "exceeds the limit" in log and "leaves the workspace" in log and "not finite" in log
    assert fast.spec.n_grippers == 1

    # NaN keypoints are refused by the planner (the last good ones stay)
    bad = Keypoints(names=["bottom_left"], points=[Point(x=math.nan, y=0.0, z=0.0)], vertex_ids=[-1])
    deadline = time.monotonic() + 10  # republished until delivered: discovery may drop the first
    while "keypoints ignored" not in _log(launcher, "fold_planner_node") and time.monotonic() < deadline:
        client.keypoints_pub.publish(bad)
        time.sleep(0.3)
    assert "keypoints ignored" in _log(launcher, "fold_planner_node")
    assert client.plan("left_side", execute=False).success
    # missing keypoints: valid message, but the fold cannot be built from it
    missing = Keypoints(names=["neck_left"], points=[Point()], vertex_ids=[-1])
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline:  # republished: the model keypoints come back every 0.5 s
        client.keypoints_pub.publish(missing)
        r = client.plan("middle", execute=False, wait_for_keypoints=False)
        if not r.success:
            break
    assert not r.success and "missing" in r.message

    # two grippers: the side fold runs after all that, model keypoints republished meanwhile
    time.sleep(0.6)
    before = client.result_count()
    r = client.plan("left_side", execute=True, timeout=30)
    assert r.success, r.message
    res = client.wait_result("left_side", 60, after=before)
    assert res.success and res.stage == 2
    assert len(fold_spec_from_msg(r.spec).spec.start_poses) == 2
    assert np.isfinite(res.height_ratio)
