"""Which state a cloud shows between folds (`perception.tracking.estimate_state`): the prior's
lines, the prior's shape with every line refitted, a fresh fit, a failed fold, laid flat again."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from clothfold_ros.folding import FOLD_SEQUENCE, fold_spec
from clothfold_ros.garment import KEYPOINT_NAMES, make_shirt
from clothfold_ros.loss import fold_target
from clothfold_ros.perception.camera import DepthCamera
from clothfold_ros.perception.estimator import BadCloudError, PoorFitError, estimate_keypoints, flat_area
from clothfold_ros.perception.tracking import FLAT_AGAIN_AREA, estimate_state, smaller_shirt
from clothfold_ros.perception.visible import visible_keypoints

T = 3e-4


def errors_mm(est, truth) -> np.ndarray:
    return np.array([np.linalg.norm((est.keypoints[n] - truth[n])[:2]) for n in KEYPOINT_NAMES]) * 1e3


@pytest.fixture(scope="module")
def sleeve_stages():
    """Shirt 1: the estimate after the left sleeve folded as planned (the prior), and the
    clouds after both sleeves with the left sleeve's line as planned and 3 cm off it (the
    cloth slid: the prior's left crease no longer lies where it was fitted)."""
    g = make_shirt(1, max_area=1e-4)
    cam = DepthCamera()
    left = fold_spec("left_sleeve", visible_keypoints(g, g.vertices, []))
    v1 = fold_target(g.vertices, left, T)
    flat = estimate_keypoints(cam.cloud(g.vertices, g.triangles, rng=0))
    prior = estimate_keypoints(cam.cloud(v1, g.triangles, rng=1), folds=["left_sleeve"], prior=flat)
    stages = {}
    for shift in (0.0, -0.03):
        s1 = dataclasses.replace(left, line_point=left.line_point + shift * left.normal)
        v = fold_target(g.vertices, s1, T)
        s2 = fold_spec("right_sleeve", visible_keypoints(g, v, [s1]), folds_done=["left_sleeve"])
        v = fold_target(v, s2, T)
        stages[shift] = (cam.cloud(v, g.triangles, rng=2), visible_keypoints(g, v, [s1, s2]))
    return g, cam, flat, prior, stages


def test_the_prior_is_taken_when_the_cloth_lies_as_fitted(sleeve_stages):
    _, _, _, prior, stages = sleeve_stages
    cloud, truth = stages[0.0]
    state = estimate_state(cloud, ["left_sleeve", "right_sleeve"], prior=prior)
    assert state.start == "prior" and len(state.tried) == 1, state.tried
    assert state.folds == ["left_sleeve", "right_sleeve"]
    assert np.median(errors_mm(state.estimate, truth)) < 5.0


def test_an_earlier_fold_that_slid_is_refitted_from_the_prior_shape(sleeve_stages):
    """The left sleeve's line 3 cm off the fitted one: the prior's kept line fits (residual
    8.4 mm, under max_residual) with keypoints 22 mm off (median) and 65 mm at worst; the
    prior's shape with both lines refitted: 2.3 mm residual, keypoints 4 mm / 18 mm."""
    _, _, _, prior, stages = sleeve_stages
    cloud, truth = stages[-0.03]
    folds = ["left_sleeve", "right_sleeve"]
    kept = estimate_keypoints(cloud, folds=folds, prior=prior)
    state = estimate_state(cloud, folds, prior=prior)
    assert state.start == "prior shape", state.tried
    assert state.estimate.shape == prior.shape  # the hidden parts still come from the prior
    err, err_kept = errors_mm(state.estimate, truth), errors_mm(kept, truth)
    assert np.median(err) < 6.0 and err.max() < 25.0, err
    assert np.median(err_kept) > 2 * np.median(err), (err_kept, err)
    assert state.estimate.residual < 0.5 * kept.residual


def test_a_failed_fold_the_cloud_shows_is_adopted(sleeve_stages):
    """Right sleeve reported failed, yet folded: the expected state (left sleeve only) does
    not fit, the left sleeve + right sleeve from the prior does."""
    _, _, _, prior, stages = sleeve_stages
    cloud, truth = stages[0.0]
    state = estimate_state(cloud, ["left_sleeve"], prior=prior, failed="right_sleeve")
    assert state.start == "failed fold" and state.folds == ["left_sleeve", "right_sleeve"], state.tried
    assert np.median(errors_mm(state.estimate, truth)) < 5.0


def test_a_folded_shirt_fitted_as_a_smaller_flat_one_is_not_taken_as_laid_flat_again(sleeve_stages):
    """A cloud is the shirt laid flat again only when the flat fit is as large as the flat shirt
    first seen (FLAT_AGAIN_AREA): after the sleeve folds (and a side fold, in a demo where
    planning from it failed the next fold) a free flat fit finds a much smaller shirt."""
    g, cam, flat, _, stages = sleeve_stages
    assert flat_area(flat.shape) == pytest.approx(flat_area(g.shape), rel=0.05)
    cloud, _ = stages[0.0]
    try:
        folded_as_flat = estimate_keypoints(cloud)
    except PoorFitError as err:  # the outline may fit badly too: its shape is what is compared
        folded_as_flat = err.estimate
    again = estimate_keypoints(cam.cloud(g.vertices, g.triangles, rng=3))
    first = flat_area(flat.shape)
    assert flat_area(folded_as_flat.shape) < FLAT_AGAIN_AREA * first
    assert "the area of the one seen flat" in smaller_shirt(folded_as_flat, first)
    assert smaller_shirt(again, first) is None
    assert smaller_shirt(folded_as_flat, None) is None  # never seen flat: nothing to compare with
    # the whole chain: sleeves expected, the shirt lies flat again: taken as flat
    state = estimate_state(cam.cloud(g.vertices, g.triangles, rng=4), ["left_sleeve", "right_sleeve"],
                           flat_shirt_area=first)
    assert state.start == "flat again" and state.folds == [], state.tried


def test_bad_clouds_and_no_fitting_state_raise():
    with pytest.raises(BadCloudError):
        estimate_state(np.zeros((0, 3)), ["left_sleeve"])
    rng = np.random.default_rng(1)
    r, a = 0.35 * np.sqrt(rng.random(20000)), rng.uniform(0, 2 * np.pi, 20000)
    disc = np.column_stack([r * np.cos(a), r * np.sin(a), np.full(20000, 0.001)])
    with pytest.raises(PoorFitError, match="residual") as info:
        estimate_state(disc, [])
    assert info.value.estimate.residual > 0.01
    assert list(FOLD_SEQUENCE[:2]) == ["left_sleeve", "right_sleeve"]


def test_a_fresh_fit_of_a_smaller_shirt_is_not_taken(sleeve_stages):
    """Without the prior, the expected left sleeve alone fits the both-sleeves cloud as a
    shirt with short sleeves (3.4 mm residual); the shirt does not shrink, so that fit is
    refused with a warning, and with nothing else fitting the cloud is rejected."""
    _, _, flat, _, stages = sleeve_stages
    cloud, _ = stages[0.0]
    first = flat_area(flat.shape)
    loose = estimate_state(cloud, ["left_sleeve"])
    assert loose.start == "fresh" and flat_area(loose.estimate.shape) < FLAT_AGAIN_AREA * first
    with pytest.raises(PoorFitError, match="only a smaller shirt"):
        estimate_state(cloud, ["left_sleeve"], flat_shirt_area=first)


def test_with_no_fold_done_a_smaller_flat_shirt_is_a_new_shirt():
    """The size check guards folded states only: laid flat with no fold done, a smaller shirt
    (shape 1 at 80 % scale) lying 58 cm from the last estimate is taken from a fresh fit."""
    from dataclasses import replace

    from clothfold_ros.garment import SHAPES

    big = make_shirt(1, max_area=1e-4)
    cam = DepthCamera()
    prior = estimate_keypoints(cam.cloud(big.vertices, big.triangles, rng=0))
    small = make_shirt(replace(SHAPES[1], scale=0.8 * SHAPES[1].scale), max_area=1e-4)
    v = small.vertices + [0.5, 0.3, 0.0]  # beyond the prior fit's pose bounds (0.3 m): a fresh fit
    state = estimate_state(cam.cloud(v, small.triangles, rng=1), [], prior=prior,
                           flat_shirt_area=flat_area(prior.shape))
    assert state.start == "fresh" and state.folds == []
    assert flat_area(state.estimate.shape) < 0.8 * flat_area(prior.shape)
    assert np.median(errors_mm(state.estimate, small.keypoints(v))) < 5.0


def test_bad_fold_lists_and_areas_are_refused_before_any_fit(sleeve_stages):
    """Unknown or repeated folds and a failed fold already done were swallowed as failed
    hypotheses ('bogus' ended as the shirt laid flat again); a zero flat area divided by zero."""
    _, _, _, prior, stages = sleeve_stages
    cloud, _ = stages[0.0]
    for folds, failed, words in [(["bogus"], None, "unknown folds"), ([], "bogus", "unknown folds"),
                                 (["left_sleeve", "left_sleeve"], None, "listed twice"),
                                 (["left_sleeve"], "left_sleeve", "listed twice")]:
        with pytest.raises(ValueError, match=words):
            estimate_state(cloud, folds, prior=prior, failed=failed)
    for area in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="flat_shirt_area"):
            estimate_state(cloud, ["left_sleeve"], flat_shirt_area=area)
    with pytest.raises(ValueError, match="listed twice"):
        estimate_keypoints(cloud, folds=["left_sleeve", "left_sleeve"])


def test_when_nothing_fits_the_error_names_every_hypothesis(sleeve_stages):
    """A disc after the left sleeve: prior, prior shape, fresh and flat again all fail, and the
    error lists each with its residual before the closest one's own message."""
    _, _, flat, prior, _ = sleeve_stages
    rng = np.random.default_rng(1)
    r, a = 0.35 * np.sqrt(rng.random(20000)), rng.uniform(0, 2 * np.pi, 20000)
    disc = np.column_stack([r * np.cos(a), r * np.sin(a), np.full(20000, 0.001)])
    with pytest.raises(PoorFitError, match=r"no hypothesis fits \(prior: residual .* mm, over max_residual; "
                                           r"prior shape: .*fresh: .*flat again: .*\); the closest: fit residual"):
        estimate_state(disc, ["left_sleeve"], prior=prior, flat_shirt_area=flat_area(flat.shape))
