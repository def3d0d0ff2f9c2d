"""Folds that end early are reported on /fold/result as failures (the whole kinematic pipeline as
processes): a cancelled fold, and a fold whose backend is killed mid-motion (trajectory_node then
publishes the failure itself once the clock has stood still for its stall_timeout)."""
from __future__ import annotations

import signal
import time

import pytest

from pipeline_helpers import running_pipeline

DOMAIN = 157


def _proc(launcher, name):
    return next(p for p in launcher.procs if p.name == name)


def _wait_moving(poses, timeout=60.0):
    """Wait until the backend has made 10 steps with gripper_0 closed (its pose published each step)."""
    deadline = time.monotonic() + timeout
    n0 = len(poses)
    while len(poses) < n0 + 10:
        assert time.monotonic() < deadline, "the backend did not step"
        time.sleep(0.02)


@pytest.fixture(scope="module")
def pipeline():
    overrides = {"fold_planner_node": {"selection": "parameter", "duration": 4.0},
                 "kinematic_robot_node": {"real_time_factor": 1.0},
                 "trajectory_node": {"stall_timeout": 3.0, "failure_report_wait": 2.0, "lookahead": 2.0}}
    with pytest.MonkeyPatch.context() as mp, running_pipeline(mp, DOMAIN, "kinematic", overrides,
                                                               "test_failures_pipeline", check_alive=False) as pair:
        launcher, client = pair
        client.wait_keypoints(60)
        from geometry_msgs.msg import PoseStamped

        poses = []
        client.node.create_subscription(PoseStamped, "/gripper_0/pose", poses.append, 10)
        yield launcher, client, poses


def test_cancelled_fold_is_a_failure(pipeline):
    launcher, client, poses = pipeline
    spec = client.plan("left_sleeve", execute=False).spec
    before = client.result_count()
    handle = client.start_goal(spec)
    assert handle.accepted
    _wait_moving(poses)
    client.cancel(handle)
    res = client.wait_result("left_sleeve", 60, after=before)
    assert not res.success, res
    assert "cancelled" in res.reason or "before the end of the planned motion" in res.reason, res.reason


def test_a_cancel_after_the_whole_motion_was_sent_changes_nothing(pipeline):
    """With a 2 s lookahead every target of a 4 s fold is sent once 2 s of it have run; a cancel
    after that cannot stop the backend, so the fold ends as it would have, with one /fold/result
    (trajectory_node used to report the cancel as a second, failed result for the same fold)."""
    launcher, client, poses = pipeline
    spec = client.plan("left_sleeve", execute=False).spec
    before = client.result_count()
    handle = client.start_goal(spec)
    assert handle.accepted
    n0 = len(poses)
    deadline = time.monotonic() + 60
    while len(poses) < n0 + 65:  # 2.6 s of the motion at 0.04 s a step: all of it sent
        assert time.monotonic() < deadline, "the backend did not step"
        time.sleep(0.02)
    client.cancel(handle)
    res = client.wait_result("left_sleeve", 60, after=before)
    assert res.success, res.reason
    time.sleep(3.0)  # longer than failure_report_wait: a second result would have come
    names = [r.fold_name for r in client.results[before:]]
    assert names == ["left_sleeve"], names


def test_killed_backend_gives_a_failed_result(pipeline):
    launcher, client, poses = pipeline  # runs after the cancel test: it kills the backend
    before = client.result_count()
    r = client.plan("right_sleeve", execute=True, timeout=30, retry_refused=10.0)
    assert r.success, r.message
    _wait_moving(poses)
    launcher._signal(_proc(launcher, "kinematic_robot_node"), signal.SIGKILL)
    res = client.wait_result("right_sleeve", 60, after=before)
    assert not res.success and "clock stood still" in res.reason and "trajectory_node" in res.reason, res.reason
