"""Fold targets and loss (docs/method.md section 7)."""
from __future__ import annotations

import numpy as np
import pytest

from clothfold_ros.folding import FOLD_SEQUENCE, FoldSpec, fold_spec
from clothfold_ros.garment import make_shirt
from clothfold_ros.loss import fold_target, folded_mask, mean_vertex_distance, mirror_across_line

T = 0.318e-3  # cotton thickness (m)


@pytest.fixture(scope="module")
def shirt():
    g = make_shirt(1, max_area=1e-3, z=2 * T)
    return g, {n: fold_spec(n, g.keypoints()) for n in FOLD_SEQUENCE}


def test_folded_mask(shirt):
    g, specs = shirt
    m = folded_mask(g.vertices, specs["right_sleeve"])
    assert m.shape == (len(g.vertices),) and m.dtype == bool
    ids = g.keypoint_ids
    assert m[ids["sleeve_top_right"]] and m[ids["sleeve_bottom_right"]]
    assert not m[ids["armpit_right"]]  # on the line
    assert not any(m[ids[k]] for k in ("bottom_left", "bottom_right", "neck_middle", "sleeve_top_left"))
    assert 0.05 < m.mean() < 0.5


def test_fold_target_mirrors_and_raises(shirt):
    g, specs = shirt
    spec = specs["right_sleeve"]
    v = g.vertices
    m = folded_mask(v, spec)
    t = fold_target(v, spec, T)
    np.testing.assert_array_equal(t[~m], v[~m])  # the rest stays put
    np.testing.assert_allclose(t[m, 2], v[m, 2] + 2 * T, atol=1e-15)  # sleeve layer offset 2 t
    np.testing.assert_allclose(spec.side_of_line(t[m]), -spec.side_of_line(v[m]), atol=1e-12)
    along = spec.line_direction
    np.testing.assert_allclose(t[m] @ along, v[m] @ along, atol=1e-12)  # mirrored, not moved along
    # the cuff lands on the body (inside the hem width, above the hem)
    cuff = t[[g.keypoint_ids["sleeve_top_right"], g.keypoint_ids["sleeve_bottom_right"]]]
    assert np.all(np.abs(cuff[:, 0]) < 0.65 * 0.635 / 2) and np.all(cuff[:, 1] > -0.5 * 0.635)
    side = fold_target(v, specs["right_side"], T)
    assert np.allclose(side[folded_mask(v, specs["right_side"]), 2], 2 * T + 3 * T)
    mid = fold_target(v, specs["middle"], T)
    assert np.allclose(mid[folded_mask(v, specs["middle"]), 2], 2 * T + 4 * T)


def test_target_of_target_is_identity(shirt):
    g, specs = shirt
    for spec in specs.values():
        once = fold_target(g.vertices, spec, T)
        assert not folded_mask(once, spec).any()
        np.testing.assert_array_equal(fold_target(once, spec, T), once)


def test_folding_back_restores_xy(shirt):
    g, specs = shirt
    spec = specs["left_sleeve"]
    back = FoldSpec("back", spec.line_point, spec.line_direction, spec.end_poses, spec.start_poses,
                    spec.tilt_signs, spec.layer_offset_factor)  # same line, grippers on the other side
    v = g.vertices
    m = folded_mask(v, spec)
    twice = fold_target(fold_target(v, spec, T), back, T)
    np.testing.assert_allclose(twice[m, :2], v[m, :2], atol=1e-12)
    np.testing.assert_allclose(twice[m, 2], v[m, 2] + 4 * T, atol=1e-15)
    np.testing.assert_allclose(mirror_across_line(mirror_across_line(v, spec), spec), v, atol=1e-12)


def test_sequence_composes(shirt):
    g, specs = shirt
    t = g.vertices
    for name in FOLD_SEQUENCE:
        t = fold_target(t, specs[name], T)
    quarter = 0.65 * 0.635 / 4
    assert np.all(np.abs(t[:, 0]) <= quarter + 1e-12)  # both sides folded in
    assert np.all(specs["middle"].side_of_line(t) <= 1e-12)  # all above the middle line
    assert np.all(t[:, 2] >= 2 * T) and t[:, 2].max() == pytest.approx(2 * T + (2 + 3 + 4) * T)
    # the full sequence is far from flat, while a mesh against itself has zero loss
    assert mean_vertex_distance(g.vertices, t) > 0.05
    assert mean_vertex_distance(t, t) == 0.0


def test_mean_vertex_distance():
    a = np.random.default_rng(0).normal(size=(50, 3))
    assert mean_vertex_distance(a, a) == 0.0
    assert mean_vertex_distance(a, a + [0.003, 0.0, 0.004]) == pytest.approx(0.005)
    b = a.copy()
    b[0] += [0.0, 0.5, 0.0]
    assert mean_vertex_distance(a, b) == pytest.approx(0.5 / 50)


def test_bad_inputs(shirt):
    g, specs = shirt
    a = g.vertices
    with pytest.raises(ValueError, match="differ in shape"):
        mean_vertex_distance(a, a[:-1])
    bad = a.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        mean_vertex_distance(a, bad)
    with pytest.raises(ValueError, match="NaN"):
        fold_target(bad, specs["middle"], T)
    with pytest.raises(ValueError, match="empty"):
        mean_vertex_distance(np.zeros((0, 3)), np.zeros((0, 3)))
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        folded_mask(a[:, :2], specs["middle"])
    with pytest.raises(ValueError, match="thickness"):
        fold_target(a, specs["middle"], -T)


def test_distance_past_target_measures_along_each_vertex_fold_motion():
    from clothfold_ros.loss import distance_past_target

    start = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 5.0, 0.0]])
    target = np.array([[2.0, 0.0, 0.0], [1.0, 2.0, 0.0], [0.0, 5.0, 0.0]])  # the third does not fold
    beyond = target + np.array([[0.5, 0.3, 0.1], [0.2, -0.1, 0.0], [9.0, 9.0, 9.0]])
    # 0.5 past along +x, 0.1 short along +y; the unfolded vertex and the heights do not count
    assert distance_past_target(beyond, start, target) == pytest.approx(0.2)
    assert distance_past_target(target, start, target) == 0.0


def test_distance_past_target_refuses_nothing_folded_and_mismatched_shapes():
    from clothfold_ros.loss import distance_past_target

    flat = np.zeros((3, 3))
    with pytest.raises(ValueError, match="no vertex is folded"):
        distance_past_target(flat, flat, flat)
    with pytest.raises(ValueError, match="differ in shape"):
        distance_past_target(flat, flat, np.zeros((2, 3)))
    with pytest.raises(ValueError):
        distance_past_target(np.full((3, 3), np.nan), flat, flat + 1.0)
