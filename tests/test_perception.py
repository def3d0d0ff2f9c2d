"""Depth camera model and the point-cloud keypoint estimator: good, noisy and broken clouds."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from clothfold_ros.folding import FOLD_SEQUENCE, body_length, fold_spec
from clothfold_ros.garment import KEYPOINT_NAMES, SHAPES, ShirtShape, make_shirt
from clothfold_ros.loss import fold_target
from clothfold_ros.perception.camera import DepthCamera
from clothfold_ros.perception.estimator import (BadCloudError, EstimatorConfig, FitError, MultipleBlobsError,
                                                NoClothError, PerceptionError, PoorFitError, estimate_keypoints)
from clothfold_ros.perception.visible import apply_folds, visible_keypoints

T = 3e-4


def errors_mm(est, truth) -> np.ndarray:
    """Horizontal keypoint errors (mm) in KEYPOINT_NAMES order."""
    return np.array([np.linalg.norm((est.keypoints[n] - truth[n])[:2]) for n in KEYPOINT_NAMES]) * 1e3


def moved(g, deg: float, shift) -> np.ndarray:
    return Rotation.from_euler("z", deg, degrees=True).apply(g.vertices) + np.r_[shift, 0.0]


# -- camera ----------------------------------------------------------------------------------
def test_camera_sees_the_top_layer_only():
    g = make_shirt(1, max_area=5e-4)
    spec = fold_spec("left_sleeve", g.keypoints())
    v = fold_target(g.vertices + [0, 0, 2 * T], spec, T)
    cam = DepthCamera(noise=0.0, dropout=0.0)
    pts = cam.cloud(v, g.triangles)
    kp = g.keypoints()
    inside = (kp["sleeve_top_left"] + kp["sleeve_bottom_left"] + kp["shoulder_left"] + kp["armpit_left"]) / 4
    folded = apply_folds(inside[None, :2], [spec])[0]  # a point of the sleeve, folded onto the body
    near = np.linalg.norm(pts[:, :2] - folded, axis=1) < 0.03
    assert near.sum() > 50
    np.testing.assert_allclose(pts[near, 2], 4 * T, atol=1e-9)  # only the top layer is returned
    assert np.all(pts[:, 2] >= 2 * T - 1e-12) and np.all(pts[:, 2] <= 4 * T + 1e-12)
    flat = cam.cloud(g.vertices, g.triangles)
    a, b, c = (g.vertices[g.triangles[:, i], :2] for i in range(3))
    e1, e2 = b - a, c - a
    area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()
    assert len(flat) == pytest.approx(area / cam.pitch**2, rel=0.02)


def test_camera_noise_dropout_and_table():
    g = make_shirt(1, max_area=2e-3)
    clean = DepthCamera(noise=0.0, dropout=0.0).cloud(g.vertices, g.triangles)
    noisy = DepthCamera(noise=0.002, dropout=0.1).cloud(g.vertices, g.triangles, rng=3)
    assert len(noisy) / len(clean) == pytest.approx(0.9, abs=0.01)
    assert np.std(noisy[:, 2]) == pytest.approx(0.002, rel=0.05)
    table = DepthCamera(noise=0.0, dropout=0.0, table=True, view=(-1, 1, -0.5, 0.5), pitch=0.01)
    pts = table.cloud(g.vertices, g.triangles)
    assert len(pts) == 200 * 100 and np.count_nonzero(pts[:, 2] == 0.0) > 0.5 * len(pts)
    for bad in (dict(pitch=0.0), dict(noise=-1.0), dict(dropout=1.0), dict(view=(1, 0, 0, 1))):
        with pytest.raises(ValueError):
            DepthCamera(**bad)


# -- estimator: good and noisy clouds ------------------------------------------------------------
@pytest.mark.parametrize("shape", sorted(SHAPES))
def test_flat_shirt_clean_cloud(shape):
    g = make_shirt(shape, max_area=5e-4)
    est = estimate_keypoints(DepthCamera(noise=0.0, dropout=0.0).cloud(g.vertices, g.triangles))
    err = errors_mm(est, g.keypoints())
    assert np.median(err) < 6.0, err
    assert est.residual < 3e-3
    assert est.shape.bottom_width * est.shape.scale == pytest.approx(g.shape.bottom_width * g.shape.scale, abs=0.01)
    assert est.shape.neck_width * est.shape.scale == pytest.approx(g.shape.neck_width * g.shape.scale, abs=0.01)
    assert list(est.keypoints) == list(KEYPOINT_NAMES)


@pytest.mark.parametrize("shape, deg, shift", [(1, 20.0, (0.05, -0.03)), (2, -15.0, (-0.04, 0.05)),
                                               (3, 8.0, (0.0, 0.05))])
def test_noisy_moved_shirt(shape, deg, shift):
    """2 mm depth noise, 10 % dropout, rotated and shifted: the issue's benchmark condition."""
    g = make_shirt(shape, max_area=5e-4)
    v = moved(g, deg, shift)
    est = estimate_keypoints(DepthCamera().cloud(v, g.triangles, rng=shape))
    err = errors_mm(est, g.keypoints(v))
    assert np.median(err) < 10.0, err
    assert np.degrees(est.pose[2]) == pytest.approx(deg, abs=1.5)
    np.testing.assert_allclose(est.pose[:2], shift, atol=0.01)


def test_random_shirt_shape_is_recovered():
    shape = ShirtShape(0.70, 0.28, 0.12, 0.70, 0.93, 0.30, 0.16, 0.55, 20.0, scale=0.58)
    g = make_shirt(shape, max_area=5e-4)
    est = estimate_keypoints(DepthCamera().cloud(g.vertices, g.triangles, rng=1))
    assert np.median(errors_mm(est, g.keypoints())) < 10.0
    assert est.shape.scale == pytest.approx(0.58, abs=0.02)
    assert est.shape.sleeve_angle_deg == pytest.approx(20.0, abs=4.0)


def test_folded_states_with_the_previous_estimate_as_prior():
    """The sequence as the pipeline perceives it: each stage's cloud fitted with the folds done,
    starting from the previous stage's estimate; keypoints compared with the visible ones."""
    g = make_shirt(1, max_area=1e-4)
    cam = DepthCamera()
    v, specs = g.vertices.copy(), []
    est = estimate_keypoints(cam.cloud(v, g.triangles, rng=0))
    length = body_length(g.keypoints())  # the planner node measures it on the flat shirt
    for k, name in enumerate(FOLD_SEQUENCE):
        spec = fold_spec(name, visible_keypoints(g, v, specs), folds_done=[s.name for s in specs],
                         body_length=length)
        specs.append(spec)
        v = fold_target(v, spec, T)
        est = estimate_keypoints(cam.cloud(v, g.triangles, rng=k + 1), folds=[s.name for s in specs], prior=est)
        err = errors_mm(est, visible_keypoints(g, v, specs))
        assert np.median(err) < 10.0, (name, err)
        assert [f.name for f in est.folds] == [s.name for s in specs]
        if name == "right_side":  # planned from the perceived keypoints, the middle fold grasps like the study
            mid = fold_spec("middle", est.keypoints, folds_done=[s.name for s in specs])
            for a, b in zip(mid.start_poses, fold_spec("middle", g.keypoints()).start_poses):
                assert np.linalg.norm((a.position - b.position)[:2]) < 0.015


@pytest.mark.parametrize("shift", [-0.05, -0.02, 0.03])
def test_a_middle_fold_off_its_plan_is_fitted_where_it_landed(shift):
    """A middle fold whose line lies `shift` m along its normal (toward the hem) from the planned
    one: toward the shoulders the hem overhangs them, and a fit started from the planned line
    moved the whole shirt 6 cm instead (keypoints 59 mm off at -2 cm, the residual 3.9 mm still
    passing); the line's start offsets find it."""
    import dataclasses

    g = make_shirt(1, max_area=1e-4)
    cam = DepthCamera()
    v, specs = g.vertices.copy(), []
    est = estimate_keypoints(cam.cloud(v, g.triangles, rng=0))
    for k, name in enumerate(FOLD_SEQUENCE):
        spec = fold_spec(name, visible_keypoints(g, v, specs), folds_done=[s.name for s in specs])
        if name == "middle":
            spec = dataclasses.replace(spec, line_point=spec.line_point + shift * spec.normal)
        specs.append(spec)
        v = fold_target(v, spec, T)
        est = estimate_keypoints(cam.cloud(v, g.triangles, rng=k + 1), folds=[s.name for s in specs], prior=est)
    err = errors_mm(est, visible_keypoints(g, v, specs))
    assert np.median(err) < 10.0 and err.max() < 20.0, err
    line = est.folds[-1]
    assert abs(np.dot(line.point - specs[-1].line_point[:2], specs[-1].normal[:2])) < 0.006


def test_a_start_that_ends_in_no_shirt_is_skipped(monkeypatch):
    """Of the fits tried, one whose shape is no shirt's (e.g. neck wider than shoulders) is left
    out and the next valid one is taken; it used to fail the whole estimate (keypoint_node then
    refused the cloud)."""
    import clothfold_ros.perception.estimator as estimator

    g = make_shirt(1, max_area=1e-4)
    cam = DepthCamera()
    v, specs = g.vertices.copy(), []
    est = estimate_keypoints(cam.cloud(v, g.triangles, rng=0))
    for name in FOLD_SEQUENCE[:2]:
        specs.append(fold_spec(name, visible_keypoints(g, v, specs), folds_done=[s.name for s in specs]))
        v = fold_target(v, specs[-1], T)
    cloud = cam.cloud(v, g.triangles, rng=1)
    real, calls = estimator.ShirtShape, []

    def first_fit_is_no_shirt(*values):
        calls.append(values)
        if len(calls) == 1:
            raise ValueError("ShirtShape.neck_width must be < shoulder_width")
        return real(*values)

    monkeypatch.setattr(estimator, "ShirtShape", first_fit_is_no_shirt)
    fitted = estimate_keypoints(cloud, folds=[s.name for s in specs], config=EstimatorConfig(good_enough=0.0))
    assert len(calls) >= 2 and np.median(errors_mm(fitted, visible_keypoints(g, v, specs))) < 10.0

    def never_a_shirt(*values):
        raise ValueError("ShirtShape.neck_width must be < shoulder_width")

    monkeypatch.setattr(estimator, "ShirtShape", never_a_shirt)
    with pytest.raises(FitError, match="fitted shirt shape is invalid"):
        estimate_keypoints(cloud, folds=[s.name for s in specs], config=EstimatorConfig(max_starts=2, good_enough=0.0))


def test_table_points_are_segmented_away():
    g = make_shirt(1, max_area=5e-4)
    v = g.vertices + [0, 0, 0.003]  # a 3 mm thick layer above the table
    cam = DepthCamera(noise=0.0003, dropout=0.0, table=True, view=(-0.9, 0.9, -0.5, 0.5))
    pts = cam.cloud(v, g.triangles, rng=0)
    est = estimate_keypoints(pts, config=EstimatorConfig(min_height=0.0015))
    assert np.median(errors_mm(est, g.keypoints(v))) < 8.0
    with pytest.raises(NoClothError, match="table is not separated"):  # without the height band
        estimate_keypoints(pts, config=EstimatorConfig(min_height=-0.01))


# -- broken clouds ----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def cloud():
    g = make_shirt(1, max_area=5e-4)
    return g, DepthCamera().cloud(g.vertices, g.triangles, rng=5)


def test_empty_malformed_and_nan_clouds(cloud):
    _, pts = cloud
    with pytest.raises(BadCloudError, match="empty"):
        estimate_keypoints(np.zeros((0, 3)))
    with pytest.raises(BadCloudError, match=r"shape \(N, 3\)"):
        estimate_keypoints(pts[:, :2])
    with pytest.raises(BadCloudError, match="NaN"):
        estimate_keypoints(np.full((1000, 3), np.nan))
    bad = pts.copy()
    bad[::10] = np.nan  # a few invalid returns (dropouts as NaN) are dropped, not fatal
    assert estimate_keypoints(bad).residual < 5e-3
    with pytest.raises(ValueError, match="unknown folds"):
        estimate_keypoints(pts, folds=["collar"])


def test_no_cloth(cloud):
    _, pts = cloud
    with pytest.raises(NoClothError, match="no cloth"):
        estimate_keypoints(pts - [0, 0, 0.5])  # everything below the height band
    rng = np.random.default_rng(0)
    speck = np.column_stack([rng.uniform(0, 0.05, (500, 2)), np.full(500, 0.001)])
    with pytest.raises(NoClothError, match="largest blob"):
        estimate_keypoints(speck)


def test_two_blobs(cloud):
    _, pts = cloud
    with pytest.raises(MultipleBlobsError, match="2 separate blobs"):
        estimate_keypoints(np.vstack([pts, pts + [1.8, 0.0, 0.0]]))


def test_not_a_shirt_and_no_convergence(cloud):
    _, pts = cloud
    rng = np.random.default_rng(1)
    r, a = 0.35 * np.sqrt(rng.random(20000)), rng.uniform(0, 2 * np.pi, 20000)
    disc = np.column_stack([r * np.cos(a), r * np.sin(a), np.full(20000, 0.001)])
    with pytest.raises(PoorFitError, match="residual") as info:
        estimate_keypoints(disc)
    assert info.value.estimate.residual > 0.01
    with pytest.raises(FitError, match="did not converge"):
        estimate_keypoints(pts, config=EstimatorConfig(max_nfev=2))
    assert issubclass(PoorFitError, PerceptionError) and issubclass(PerceptionError, ValueError)


def test_camera_refuses_non_finite_meshes_and_survives_a_stretched_triangle():
    """A NaN vertex once left a silent hole; one vertex 50 m away sized every triangle's candidate
    pixel grid by its triangles' (about 42 GiB). Now: a clear error, and a stretched triangle costs
    only its own pixels in the view; the rest of the height map is unchanged."""
    g = make_shirt(1, max_area=2e-3)
    cam = DepthCamera(noise=0.0, dropout=0.0)
    bad = g.vertices.copy()
    bad[3, 2] = np.nan
    with pytest.raises(ValueError, match="finite"):
        cam.height_map(bad, g.triangles)
    with pytest.raises(ValueError, match="indices"):
        cam.height_map(g.vertices, g.triangles + len(g.vertices))
    xs, ys, ref = cam.height_map(g.vertices, g.triangles)
    far = g.vertices.copy()
    far[0] += [50.0, 0.0, 0.0]
    _, _, z = cam.height_map(far, g.triangles)
    gx, gy = np.meshgrid(xs, ys)
    away = np.hypot(gx - g.vertices[0, 0], gy - g.vertices[0, 1]) > 0.1
    away &= np.abs(gy - g.vertices[0, 1]) > 0.1  # off the stretched triangles' band toward +x
    assert np.array_equal(z[away], ref[away], equal_nan=True)
    assert np.isfinite(ref[away]).sum() > 1000
