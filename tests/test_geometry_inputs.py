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
    # the flagged names come before the config's repr (which names every field)
    with pytest.raises(ValueError, match=rf"^EstimatorConfig: bad [^(]*\b{field.split('_')[0]}"):
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


def test_core_refuses_bad_geometry_and_timing_with_the_reason():
    """From a review of the core's inputs: each of these passed silently (a NaN path time, a mesh
    of ~1e11 triangles asked of Triangle) or failed far from the cause."""
    from clothfold_ros.trajectory import GripperPath

    down = np.array([0.0, 0.0, 0.0, 1.0])
    a, b = Pose([0.0, 0.0, 0.01], down), Pose([0.2, 0.0, 0.05], down)
    path = GripperPath(a, b, control=[0.1, 0.0, 0.2], duration=4.0)
    np.testing.assert_allclose(path.position(4.0), b.position)
    with pytest.raises(ValueError, match="path time must be finite"):
        path.position(math.nan)
    with pytest.raises(ValueError, match="z axis must be a finite 3-vector"):
        Pose.from_axes(np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, math.nan, 1.0]))
    with pytest.raises(ValueError, match="3-vector position"):
        Pose(np.zeros(2), down)
    for area in (1e-19, 1e-9, 0.5):
        with pytest.raises(ValueError, match="max_area must be a triangle area"):
            make_shirt(1, max_area=area)


def test_scenarios_and_features_are_checked():
    from clothfold_ros.lookup.scenario import (SCENARIOS, Scenario, definition_features, features, flat_keypoints,
                                               normalized_distance)

    for kwargs, words in [({"shape": 7}, "shape must be one of"), ({"folds": ()}, "folds must be one or more"),
                          ({"folds": ("collar",)}, "folds must be one or more"), ({"friction": -0.1}, "friction"),
                          ({"duration": 0.0}, "duration"), ({"material": "silk"}, "silk")]:
        with pytest.raises(ValueError, match=words):
            Scenario("x", "x", **kwargs)
    with pytest.raises(ValueError, match="shape must be one of"):
        flat_keypoints(7, "cotton")
    kp = flat_keypoints(1, "cotton")
    args = dict(fold_name="left_sleeve", keypoints=kp, material_name="cotton", friction=0.5, duration=4.0)
    for extra, words in [({"grip": -1.0}, "grip distance"), ({"stage": -3}, "stage must be"),
                         ({"stage": math.nan}, "stage must be"), ({"stage": 1.5}, "stage must be")]:
        with pytest.raises(ValueError, match=words):
            features(**args, **extra)
    f = definition_features(SCENARIOS["shape1"])
    assert normalized_distance(f, f) == 0.0
    with pytest.raises(ValueError, match="lacks finite fold_type"):
        normalized_distance(f, {**f, "fold_type": math.nan})
    with pytest.raises(ValueError, match="lacks finite stage"):
        normalized_distance({k: v for k, v in f.items() if k != "stage"}, f)
