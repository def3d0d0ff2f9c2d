"""Pure parts of the nodes: lock-step bookkeeping and motion limits."""
from __future__ import annotations

import numpy as np
import pytest

from clothfold_ros.folding import fold_spec
from clothfold_ros.garment import make_shirt
from clothfold_ros.nodes.limits import check_trajectory
from clothfold_ros.nodes.lockstep import LockStep
from clothfold_ros.pose import Pose
from clothfold_ros.trajectory import FoldTrajectory

MS = 1_000_000


def pose(x):
    return Pose(np.array([x, 0.0, 0.1]), np.array([0.0, 0.0, 0.0, 1.0]))


def test_lockstep_steps_only_with_the_next_target():
    ls = LockStep(2, 0.04)
    ls.add_command(0, 100 * MS, True)
    ls.advance_free(500 * MS)
    assert ls.now_ns == 100 * MS  # the free clock stops at the pending command
    assert ls.due_command().gripper == 0
    for k in range(5):
        ls.add_target(0, 100 * MS + 10 * MS * k, pose(0.01 * k))
    ls.pop_command()
    ls.close(0)
    assert ls.target_now(0).position[0] == 0.0
    got = ls.step_targets()
    assert got is not None and got[0].position[0] == pytest.approx(0.04)
    ls.stepped()
    assert ls.now_ns == 140 * MS and ls.step_targets() is None  # 180 ms not there yet
    ls.add_target(0, 190 * MS, pose(0.09))
    assert ls.step_targets()[0].position[0] == pytest.approx(0.08)  # interpolated 180 ms
    with pytest.raises(ValueError, match="after the clock passed"):
        ls.add_command(0, 50 * MS, False)
    with pytest.raises(ValueError, match="out of range"):
        ls.add_target(2, 0, pose(0))


def test_lockstep_hold_until_announced_start():
    ls = LockStep(1, 0.04)
    ls.hold_until = 30 * MS
    ls.advance_free(100 * MS)
    assert ls.now_ns == 30 * MS
    ls.close(0)
    assert ls.hold_until is None
    ls.abort()
    assert not ls.closed and not ls.pending


def test_limits():
    g = make_shirt(1, max_area=5e-3)
    spec = fold_spec("left_sleeve", g.keypoints())
    traj = FoldTrajectory(spec, 0.5, 30.0, 4.0)
    assert check_trajectory(traj, 100.0, [-1, -1, 0], [1, 1, 1], 1.0, 2) is None
    assert "speed" in check_trajectory(FoldTrajectory(spec, 0.5, 30.0, 0.5), 100.0, [-1, -1, 0], [1, 1, 1], 1.0, 2)
    assert "workspace" in check_trajectory(traj, 100.0, [-1, -1, 0], [1, 1, 0.05], 1.0, 2)
    two = fold_spec("middle", g.keypoints())
    assert "grippers" in check_trajectory(FoldTrajectory(two, 0.5, 30.0, 4.0), 100.0, [-1, -1, 0], [1, 1, 1], 1.0, 1)
