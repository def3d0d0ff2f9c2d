"""Clouds that hold the table: the cloth told from the table by colour (perception/colour.py),
the packed RGB of PointCloud2 (PCL's `rgb`), and the estimator on such a cloud with and
without the colour mask. A cotton shirt lies 0.3 mm thick on the table, under the camera's
depth noise: no height band separates it."""
from __future__ import annotations

import numpy as np
import pytest

from clothfold_ros.garment import make_shirt
from clothfold_ros.perception.camera import DepthCamera
from clothfold_ros.perception.colour import off_table_colour, pack_rgb, unpack_rgb
from clothfold_ros.perception.estimator import EstimatorConfig, NoClothError, estimate_keypoints


def _errors_mm(est, truth) -> np.ndarray:
    return np.array([np.linalg.norm(est.keypoints[n][:2] - truth[n][:2]) * 1e3 for n in truth])


def test_packed_rgb_round_trip_and_pcl_layout():
    rgb = np.array([[255, 0, 0], [0, 128, 255], [1, 2, 3]])
    packed = pack_rgb(rgb)
    assert packed.tolist() == [0xFF0000, 0x0080FF, 0x010203]  # PCL: 0x00RRGGBB
    np.testing.assert_array_equal(unpack_rgb(packed), rgb)
    # stored as the bits of a float32 field, as PCL and camera drivers do
    np.testing.assert_array_equal(unpack_rgb(packed.view(np.float32).view(np.uint32)), rgb)
    with pytest.raises(ValueError, match="uint32"):
        unpack_rgb(packed.astype(np.float64))
    with pytest.raises(ValueError, match="0..255"):
        pack_rgb(np.array([[256, 0, 0]]))


def test_off_table_colour_and_its_refusals():
    rgb = np.array([[60, 45, 35], [70, 50, 40], [200, 205, 215]])
    assert off_table_colour(rgb, [60, 45, 35], 30.0).tolist() == [False, False, True]
    for table, dist, words in (([60, 45], 30.0, "3 values"), ([60, 45, 300], 30.0, "3 values"),
                               ([60, 45, 35], 0.0, "colour distance"), ([60, 45, 35], 500.0, "colour distance")):
        with pytest.raises(ValueError, match=words):
            off_table_colour(rgb, table, dist)


def test_a_cloud_with_the_table_is_fitted_after_the_colour_mask():
    g = make_shirt(1, max_area=5e-4)
    cam = DepthCamera(table=True)  # the default depth noise (2 mm) is 6x the cloth's thickness
    pts, rgb = cam.colour_cloud(g.vertices, g.triangles, rng=0)
    assert np.array_equal(pts, cam.cloud(g.vertices, g.triangles, rng=0))  # the same points as `cloud`
    with pytest.raises(NoClothError, match="table is not separated"):
        estimate_keypoints(pts, config=EstimatorConfig())
    with pytest.raises(NoClothError, match="table is not separated"):  # nor does a height band help
        estimate_keypoints(pts, config=EstimatorConfig(min_height=0.001))
    cloth = off_table_colour(rgb, cam.table_rgb, 60.0)
    assert 0.05 < cloth.mean() < 0.3  # the shirt is a small part of the view
    est = estimate_keypoints(pts[cloth], config=EstimatorConfig())
    assert np.median(_errors_mm(est, g.keypoints())) < 10.0


def test_keypoint_node_refuses_a_half_set_table_colour():
    from clothfold_ros.nodes.keypoint_node import _cross_check

    base = {"min_height": -0.01, "max_height": 0.25}
    assert _cross_check({**base, "table_color": [-1.0, -1.0, -1.0]}, []) is None  # off
    assert _cross_check({**base, "table_color": [60.0, 45.0, 35.0]}, []) is None
    assert "table_color [-1.0, 45.0, 35.0] must be three values" in _cross_check(
        {**base, "table_color": [-1.0, 45.0, 35.0]}, ["table_color"])


def test_the_nan_share_is_judged_on_the_whole_cloud():
    """Invalid returns (NaN, of any colour the driver gives them) in 13 % of a cloud that holds
    the table: fitted, as without the table; judged after the mask they would be over half of
    what is left and the cloud refused. Over half the cloud NaN is refused as before."""
    from clothfold_ros.perception.colour import cloth_points
    from clothfold_ros.perception.estimator import BadCloudError

    g = make_shirt(1, max_area=5e-4)
    cam = DepthCamera(table=True)
    pts, rgb = cam.colour_cloud(g.vertices, g.triangles, rng=1)
    rng = np.random.default_rng(2)
    holes = rng.random(len(pts)) < 0.13
    pts[holes], rgb[holes] = np.nan, 0  # black, as some drivers colour invalid pixels
    kept = cloth_points(pts, rgb, cam.table_rgb, 60.0)
    assert np.isfinite(kept).all() and len(kept) < 0.3 * len(pts)
    assert holes.sum() > len(kept)  # what the estimator would have judged: more NaN than shirt
    est = estimate_keypoints(kept, config=EstimatorConfig())
    assert np.median(_errors_mm(est, g.keypoints())) < 10.0
    pts[rng.random(len(pts)) < 0.6] = np.nan
    with pytest.raises(BadCloudError, match="NaN/inf"):
        cloth_points(pts, rgb, cam.table_rgb, 60.0)
    with pytest.raises(ValueError, match="colours for"):
        cloth_points(pts, rgb[:-1], cam.table_rgb, 60.0)
