"""FoldPlan: the one fold type from the planner to the simulator, checked when built."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from clothfold_ros.folding import fold_spec
from clothfold_ros.garment import make_shirt
from clothfold_ros.plan import FoldPlan


@pytest.fixture(scope="module")
def spec():
    return fold_spec("left_side", make_shirt(1, max_area=2e-3).keypoints())


def test_a_plan_carries_its_trajectory(spec):
    plan = FoldPlan(spec, 0.45, 30.0, 4.0, 0.2, stage=2)
    traj = plan.trajectory
    assert (traj.height_ratio, traj.tilt_deg, traj.duration) == (0.45, 30.0, 4.0)
    assert len(traj.paths) == spec.n_grippers == 2
    np.testing.assert_allclose(traj.poses_at(0.0)[1].position, spec.start_poses[1].position, atol=1e-12)
    moved = dataclasses.replace(plan, tilt_deg=10.0)  # a changed plan is checked and rebuilt again
    assert moved.trajectory.tilt_deg == 10.0 and plan.trajectory.tilt_deg == 30.0


@pytest.mark.parametrize("change, match", [
    (dict(height_ratio=0.0), "height ratio"), (dict(height_ratio=math.nan), "height ratio"),
    (dict(tilt_deg=-1.0), "tilt"), (dict(tilt_deg=math.inf), "tilt"),
    (dict(duration=0.0), "duration"), (dict(settle_time=-0.1), "settle_time"),
    (dict(settle_time=math.nan), "settle_time"), (dict(stage=-1), "stage"), (dict(stage=1.5), "stage"),
    (dict(spec="left_side"), "FoldSpec"),
])
def test_an_invalid_plan_is_refused_when_built(spec, change, match):
    args = dict(spec=spec, height_ratio=0.45, tilt_deg=30.0, duration=4.0, settle_time=0.2, stage=0) | change
    with pytest.raises(ValueError, match=match):
        FoldPlan(**args)
