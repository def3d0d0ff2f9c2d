"""Bad numbers given to the geometry and perception core are a ValueError naming what is wrong,
not a NaN, an IndexError or a crash later (a review's list: NaN tilt sign, infinite stage and
modulus, a zero gripper axis, impossible estimator settings, malformed fold lines)."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from clothfold_ros.folding import fold_spec
from clothfold_ros.garment import make_shirt
from clothfold_ros.materials import material
from clothfold_ros.perception.estimator import EstimatorConfig
from clothfold_ros.perception.visible import FoldLine
from clothfold_ros.plan import FoldPlan
from clothfold_ros.pose import Pose
from clothfold_ros.trajectory import bezier_control_point


def test_tilt_sign_must_be_a_sign():
    args = (np.zeros(3), np.array([0.2, 0.0, 0.0]), np.array([0.1, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), 0.5, 30.0)
    assert np.isfinite(bezier_control_point(*args, tilt_sign=-1.0)).all()
    for bad in (math.nan, 0.0, math.inf):
        with pytest.raises(ValueError, match="tilt_sign"):
            bezier_control_point(*args, tilt_sign=bad)


def test_stage_modulus_and_gripper_axis():
    spec = fold_spec("left_sleeve", make_shirt(1, max_area=5e-3).keypoints())
    assert FoldPlan(spec, 0.5, 30.0, stage=np.int64(2)).stage == 2
    for bad in (math.inf, math.nan, 1.5, -1):
        with pytest.raises(ValueError, match="stage"):
            FoldPlan(spec, 0.5, 30.0, stage=bad)
    with pytest.raises(ValueError, match="finite and > 0"):
        dataclasses.replace(material("cotton"), youngs_modulus=math.inf)
    with pytest.raises(ValueError, match="x axis"):
        Pose.from_axes(np.zeros(3), np.zeros(3), np.array([0.0, 0.0, 1.0]))


@pytest.mark.parametrize("field,value", [("pixel", -0.005), ("pixel", math.nan), ("contour_points", 0),
                                         ("min_points", 0), ("blob_fraction", 2.0), ("min_area", 5.0),
                                         ("max_height", -1.0), ("tolerance", 0.0)])
def test_estimator_settings_are_checked(field, value):
    with pytest.raises(ValueError, match=field.split("_")[0]):
        EstimatorConfig(**{field: value})


def test_fold_lines_are_checked():
    line = FoldLine("left_side", [0.1, 0.0], [1.0, 0.0], 0.002)
    assert isinstance(line.point, np.ndarray) and line.kind == "side"
    for kwargs, words in [(dict(name="diagonal"), "unknown fold"), (dict(normal=[2.0, 0.0]), "unit vector"),
                          (dict(point=[0.1, 0.0, 0.0]), r"\(2,\) arrays"), (dict(crease=-0.001), "crease"),
                          (dict(point=[math.nan, 0.0]), "finite")]:
        with pytest.raises(ValueError, match=words):
            FoldLine(**{**dict(name="left_side", point=[0.1, 0.0], normal=[1.0, 0.0]), **kwargs})


def test_pose_quaternions_are_normalised_or_refused():
    """A quaternion of huge components is normalised (its plain norm overflows to inf, which
    made it the zero quaternion); a zero or NaN one is refused."""
    q = Pose(np.zeros(3), [1e200, 0.0, 0.0, 1e200]).quaternion
    np.testing.assert_allclose(q, [2 ** -0.5, 0.0, 0.0, 2 ** -0.5])
    np.testing.assert_allclose(Pose(np.zeros(3), [0.0, 0.0, 0.0, 3.0]).quaternion, [0, 0, 0, 1])
    for bad in ([0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1e-12], [np.nan, 0.0, 0.0, 1.0]):
        with pytest.raises(ValueError):
            Pose(np.zeros(3), bad)
