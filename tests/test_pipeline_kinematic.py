"""The unchanged pipeline against kinematic_robot_node (separate processes), and the bad inputs
every node must survive while it keeps serving: unknown folds, NaN, foreign-frame, duplicate or
partial keypoint sets, a new fold while one runs, goals outside the search space, motions outside
the workspace or faster than the speed limit."""
from __future__ import annotations

import copy
import math
import os
import re
import signal
import time
from copy import deepcopy

import numpy as np
import pytest
from clothfold_msgs.msg import Keypoints
from geometry_msgs.msg import Point

from pipeline_helpers import FAST_KINEMATIC, running_pipeline

from clothfold_ros.nodes.conversions import fold_spec_from_msg, time_to_ns

DOMAIN = 151
# Real time: the 2-s fold must still run when the second plan request arrives. At 4x (0.5 s of
# wall time) it once ended before the planner's first reply (0.64 s under a loaded machine).
REAL_TIME_KINEMATIC = {**FAST_KINEMATIC, "kinematic_robot_node": {"real_time_factor": 1.0}}


@pytest.fixture
def pipeline(monkeypatch):
    with running_pipeline(monkeypatch, DOMAIN, "kinematic", REAL_TIME_KINEMATIC, "test_pipeline_kinematic") as pair:
        yield pair  # a node that died fails the test


def _log(launcher, name):
    return "\n".join(next(p for p in launcher.procs if p.name == name).lines)


def _starts(spec) -> np.ndarray:
    """(G, 3) gripper start positions of a FoldSpec message (m): what the keypoints decide."""
    return np.array([[p.position.x, p.position.y, p.position.z] for p in spec.start_poses])


def _wait_log(launcher, name, words, timeout=20):
    """Wait for a line of the node's output containing words (output arrives through a pipe)."""
    launcher.wait_for(next(p for p in launcher.procs if p.name == name), re.escape(words), timeout)


def test_kinematic_pipeline_and_bad_inputs(pipeline):
    launcher, client = pipeline
    # the model's set, taken before this test publishes bad sets on the same topic (the client
    # hears its own messages: a later wait_keypoints may return one of them)
    good_kp = client.wait_keypoints(60)
    assert len(good_kp.names) == 13 and np.isfinite([[p.x, p.y, p.z] for p in good_kp.points]).all()

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
    _wait_log(launcher, "trajectory_node", "still running")

    # goals straight to trajectory_node: too fast, outside the workspace, NaN, below the table
    good = client.plan("right_sleeve", execute=False).spec
    fast_msg = type(good)(**{k: getattr(good, k) for k in good.get_fields_and_field_types()})
    fast_msg.duration = 0.6
    assert not client.send_goal(fast_msg)
    far = deepcopy(good)  # its own poses: a shallow copy would move good's end too
    far.end_poses[0].position.x = 5.0
    assert not client.send_goal(far)
    nan = type(good)(**{k: getattr(good, k) for k in good.get_fields_and_field_types()})
    nan.tilt_deg = math.nan
    assert not client.send_goal(nan)
    low = deepcopy(good)
    low.start_poses[0].position.z = -0.05
    assert not client.send_goal(low)
    for words in ("exceeds the limit", "leaves the workspace", "not finite", "below the table top"):
        _wait_log(launcher, "trajectory_node", words)

    # goals outside the search space / the sane ranges are refused with the reason
    def copy(**changes):
        m = type(good)(**{k: getattr(good, k) for k in good.get_fields_and_field_types()})
        for k, v in changes.items():
            setattr(m, k, v)
        return m

    two_faults = deepcopy(good)  # outside the search space and below the table: the search space is named
    two_faults.tilt_deg, two_faults.start_poses[0].position.z = 80.0, -0.05
    refusals = {"tilt_deg = 80 deg is outside [0, 60]": two_faults,
                "height_ratio = 1.5 is outside [0.1, 1]": copy(height_ratio=1.5),
                "height_ratio = 0.05 is outside": copy(height_ratio=0.05),
                "tilt_deg = 90 deg is outside [0, 60]": copy(tilt_deg=90.0),
                "unknown fold 'foo'": copy(fold_name="foo"),
                "duration = 10000 s is outside [0.5, 60]": copy(duration=1e4),
                "duration = 1e+12 s is outside": copy(duration=1e12)}
    for words, msg in refusals.items():
        assert not client.send_goal(msg), words
    for words in refusals:
        _wait_log(launcher, "trajectory_node", words)

    # Bad keypoint sets, refused by the planner with the reason: the last good set stays. The model
    # source republishes the good set every 0.5 s, which would hide a bad set the planner took:
    # keypoint_node is paused (SIGSTOP) meanwhile, once the planner has a set newer than the fold.
    # stamped no earlier than the fold's result (the clock stands still after it: at its stamp)
    latest = client.wait_keypoints(30, newer_than_ns=time_to_ns(res.header.stamp) - 1)
    kp_proc = next(p for p in launcher.procs if p.name == "keypoint_node")
    os.kill(kp_proc.pid, signal.SIGSTOP)
    try:
        _bad_keypoints_are_refused(launcher, client, latest)
    finally:
        os.kill(kp_proc.pid, signal.SIGCONT)

    # two grippers: the side fold runs after all that, model keypoints republished meanwhile
    time.sleep(0.6)
    before = client.result_count()
    r = client.plan("left_side", execute=True, timeout=30)
    assert r.success, r.message
    res = client.wait_result("left_side", 60, after=before)
    assert res.success and res.stage == 2
    assert len(fold_spec_from_msg(r.spec).spec.start_poses) == 2
    assert np.isfinite(res.height_ratio)


def _bad_keypoints_are_refused(launcher, client, good_kp):
    """Bad sets stamped like the good one (a current set: the planner's check of the stamp against
    the last fold does not refuse them)."""
    ref = client.plan("middle", execute=False)  # from the good set (retried until the planner has it)
    assert ref.success, ref.message
    # NaN keypoints
    bad = Keypoints(header=copy.deepcopy(good_kp.header), names=list(good_kp.names), points=list(good_kp.points),
                    vertex_ids=list(good_kp.vertex_ids))
    bad.points[0] = Point(x=math.nan, y=0.0, z=0.0)
    deadline = time.monotonic() + 10  # republished until delivered: discovery may drop the first
    while "keypoints ignored" not in _log(launcher, "fold_planner_node") and time.monotonic() < deadline:
        client.keypoints_pub.publish(bad)
        time.sleep(0.3)
    assert "keypoints ignored" in _log(launcher, "fold_planner_node")
    r = client.plan("left_side", execute=False, wait_for_keypoints=False)
    assert r.success, r.message  # taken, the NaN set would give no plan
    # a partial set, a foreign frame, duplicate names (every name, one twice). Their points are the
    # good ones moved 0.3 m: a plan made from one of them would move the grippers' start poses
    moved = [Point(x=p.x + 0.3, y=p.y - 0.3, z=p.z) for p in good_kp.points]
    partial = Keypoints(header=copy.deepcopy(good_kp.header), names=list(good_kp.names[:-1]), points=moved[:-1],
                        vertex_ids=list(good_kp.vertex_ids[:-1]))
    foreign = Keypoints(header=copy.deepcopy(good_kp.header), names=list(good_kp.names), points=moved,
                        vertex_ids=list(good_kp.vertex_ids))
    foreign.header.frame_id = "camera"
    dup = Keypoints(header=copy.deepcopy(good_kp.header), names=list(good_kp.names) + [good_kp.names[0]],
                    points=moved + [moved[0]], vertex_ids=list(good_kp.vertex_ids) + [good_kp.vertex_ids[0]])
    for msg, words in ((partial, "incomplete set"), (foreign, "frame is 'camera'"), (dup, "duplicate names")):
        deadline = time.monotonic() + 10
        while words not in _log(launcher, "fold_planner_node") and time.monotonic() < deadline:
            client.keypoints_pub.publish(msg)
            time.sleep(0.3)
        assert words in _log(launcher, "fold_planner_node"), words
        r = client.plan("middle", execute=False, wait_for_keypoints=False)
        assert r.success, (words, r.message)
        np.testing.assert_allclose(_starts(r.spec), _starts(ref.spec), atol=1e-9, err_msg=words)
