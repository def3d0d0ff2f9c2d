"""Fold specifications from keypoints (docs/method.md section 5)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from clothfold_ros.folding import FOLD_NAMES, FOLD_SEQUENCE, LAYER_OFFSET_FACTOR, FoldSpec, fold_spec
from clothfold_ros.garment import KEYPOINT_NAMES, SHAPES, shirt_outline
from clothfold_ros.pose import Pose
from clothfold_ros.trajectory import bezier_control_point

S = 0.635
W = 0.65 * S  # hem width of shape 1 (m)
UP = np.array([0.0, 0.0, 1.0])


def keypoints(shape: int = 1, z: float = 0.0) -> dict[str, np.ndarray]:
    out = shirt_outline(shape)
    return {n: np.array([x, y, z]) for n, (x, y) in zip(KEYPOINT_NAMES, out)}


def line_distance(spec: FoldSpec, p: np.ndarray) -> float:
    r = p - spec.line_point
    return float(np.linalg.norm((r - (r @ spec.line_direction) * spec.line_direction)[:2]))


def test_names_sequence_offsets():
    assert FOLD_NAMES == ("left_sleeve", "right_sleeve", "left_side", "right_side", "middle")
    assert FOLD_SEQUENCE == FOLD_NAMES
    assert LAYER_OFFSET_FACTOR == {"sleeve": 2.0, "side": 3.0, "middle": 4.0}
    kp = keypoints()
    assert [fold_spec(n, kp).layer_offset_factor for n in FOLD_NAMES] == [2, 2, 3, 3, 4]
    assert [fold_spec(n, kp).n_grippers for n in FOLD_NAMES] == [1, 1, 2, 2, 1 + 1]


@pytest.mark.parametrize("side, sx", [("right", 1.0), ("left", -1.0)])
def test_sleeve_line_and_gripper(side, sx):
    kp = keypoints()
    spec = fold_spec(f"{side}_sleeve", kp)
    np.testing.assert_allclose(spec.line_point, kp[f"armpit_{side}"])
    d = spec.line_direction
    # 30 deg from the (vertical) side seam, leaning toward the neck: going up, |x| shrinks
    assert abs(d[1]) == pytest.approx(math.cos(math.radians(30)))
    up_along = d * np.sign(d[1])
    assert sx * up_along[0] == pytest.approx(-0.5)
    expected = {"right": [0.5, -math.sqrt(3) / 2, 0.0], "left": [0.5, math.sqrt(3) / 2, 0.0]}[side]
    np.testing.assert_allclose(d, expected, atol=1e-12)  # (bottom - armpit) rotated by 30 / 150 deg
    (start,) = spec.start_poses
    cuff = (kp[f"sleeve_top_{side}"] + kp[f"sleeve_bottom_{side}"]) / 2
    np.testing.assert_allclose(start.position, cuff)
    target = (kp[f"shoulder_{side}"] + kp[f"armpit_{side}"]) / 2
    approach = (target - cuff) / np.linalg.norm(target - cuff)
    r = start.matrix
    np.testing.assert_allclose(r[:, 0], UP, atol=1e-12)
    np.testing.assert_allclose(r[:, 2], approach, atol=1e-12)
    np.testing.assert_allclose(r[:, 1], np.cross(r[:, 2], r[:, 0]), atol=1e-12)


@pytest.mark.parametrize("side, sx", [("right", 1.0), ("left", -1.0)])
def test_side_fold(side, sx):
    kp = keypoints()
    spec = fold_spec(f"{side}_side", kp)
    assert spec.line_point[0] == pytest.approx(sx * W / 4)  # a quarter of the hem width in
    np.testing.assert_allclose(np.abs(spec.line_direction), [0, 1, 0], atol=1e-12)
    grips = [p.position for p in spec.start_poses]
    np.testing.assert_allclose(grips, [kp[f"armpit_{side}"], kp[f"bottom_{side}"]])
    for p in spec.start_poses:  # approach toward the shirt centre (origin)
        np.testing.assert_allclose(p.matrix[:, 2], -p.position / np.linalg.norm(p.position), atol=1e-12)
        np.testing.assert_allclose(p.matrix[:, 0], UP, atol=1e-12)


def test_middle_fold():
    kp = keypoints()
    spec = fold_spec("middle", kp)
    shoulder_y, hem_y = (0.9 - 0.5) * S, -0.5 * S
    assert spec.line_point[1] == pytest.approx((shoulder_y + hem_y) / 2)
    np.testing.assert_allclose(np.abs(spec.line_direction), [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose([p.position for p in spec.start_poses], [[-W / 4, hem_y, 0], [W / 4, hem_y, 0]],
                               atol=1e-12)
    for p in spec.start_poses:
        np.testing.assert_allclose(p.matrix[:, 2], [0, 1, 0], atol=1e-12)


@pytest.mark.parametrize("shape", [1, 2, 3])
@pytest.mark.parametrize("name", FOLD_NAMES)
def test_end_pose(shape, name):
    spec = fold_spec(name, keypoints(shape, z=0.001))
    for a, b in zip(spec.start_poses, spec.end_poses):
        assert b.position[2] == pytest.approx(0.05)
        assert spec.side_of_line(a.position) > 0.001 and spec.side_of_line(b.position) < 0  # far side
        # position rotated by 175 deg about the line: distance to it scales by |cos 175|
        assert line_distance(spec, b.position) == pytest.approx(
            line_distance(spec, a.position) * abs(math.cos(math.radians(175))), rel=1e-9)
        rel = b.rotation * a.rotation.inv()  # orientation rotated by 175 deg about the line
        rotvec = rel.as_rotvec()
        assert np.linalg.norm(rotvec) == pytest.approx(math.radians(175))
        assert abs(rotvec @ spec.line_direction) == pytest.approx(math.radians(175))
        assert b.matrix[2, 0] == pytest.approx(math.cos(math.radians(175)))  # gripper x nearly down
        # over the top: a 90 deg rotation in the same sense lifts the start point
        mid = spec.line_point + Rotation.from_rotvec(rotvec / 175 * 90).apply(a.position - spec.line_point)
        assert mid[2] > a.position[2] + 0.9 * line_distance(spec, a.position)


def test_end_angle_near_180_mirrors_and_height_is_configurable():
    kp = keypoints()
    spec = fold_spec("right_sleeve", kp, end_angle_deg=179.9, end_height=0.02)
    (a,), (b,) = spec.start_poses, spec.end_poses
    assert b.position[2] == pytest.approx(0.02)
    assert spec.side_of_line(b.position) == pytest.approx(-spec.side_of_line(a.position), rel=1e-4)
    # a half turn has no shortest sense: the interpolated orientation could turn against the fold
    with pytest.raises(ValueError, match=r"end_angle_deg must be in \(0, 180\) deg, got 180"):
        fold_spec("right_sleeve", kp, end_angle_deg=180.0)


def test_side_of_line_vectorised():
    spec = fold_spec("right_sleeve", keypoints())
    pts = np.array([spec.line_point, spec.start_poses[0].position, spec.line_point + 0.1 * spec.line_direction])
    d = spec.side_of_line(pts)
    assert d.shape == (3,)
    assert d[0] == pytest.approx(0) and d[1] > 0.3 and d[2] == pytest.approx(0)


def _tilt_shift(spec: FoldSpec, i: int) -> np.ndarray:
    a, b = spec.start_poses[i].position, spec.end_poses[i].position
    args = (a, b, spec.line_point, spec.line_direction, 0.5)
    return (bezier_control_point(*args, 30.0, spec.tilt_signs[i]) - bezier_control_point(*args, 0.0, 1.0))


def test_tilt_signs_bow_outward():
    kp = keypoints()
    for side in ("left", "right"):
        spec = fold_spec(f"{side}_sleeve", kp)
        toward_shoulder = kp[f"shoulder_{side}"] - kp[f"armpit_{side}"]
        assert _tilt_shift(spec, 0) @ (spec.line_direction * np.sign(spec.line_direction @ toward_shoulder)) > 0.01
        spec = fold_spec(f"{side}_side", kp)  # grippers 0 = armpit (top), 1 = bottom
        assert _tilt_shift(spec, 0)[1] > 0.01 and _tilt_shift(spec, 1)[1] < -0.01
    spec = fold_spec("middle", kp)  # grippers 0 = left (-x), 1 = right
    assert _tilt_shift(spec, 0)[0] < -0.01 and _tilt_shift(spec, 1)[0] > 0.01
    assert set(spec.tilt_signs) == {-1.0, 1.0}


@pytest.mark.parametrize("name", FOLD_NAMES)
def test_specs_follow_a_moved_shirt(name):
    """Rotating and shifting the shirt on the table moves every spec with it."""
    rot = Rotation.from_euler("z", 40, degrees=True)
    shift = np.array([0.3, -0.1, 0.0])
    kp = keypoints()
    moved = {k: rot.apply(v) + shift for k, v in kp.items()}
    a, b = fold_spec(name, kp), fold_spec(name, moved)
    assert b.side_of_line(rot.apply(a.line_point) + shift) == pytest.approx(0, abs=1e-12)
    assert abs(rot.apply(a.line_direction) @ b.line_direction) == pytest.approx(1)
    for pa, pb in zip(a.start_poses + a.end_poses, b.start_poses + b.end_poses):
        np.testing.assert_allclose(rot.apply(pa.position) + shift, pb.position, atol=1e-12)
        np.testing.assert_allclose((rot * pa.rotation).as_matrix(), pb.matrix, atol=1e-9)
    assert a.tilt_signs == b.tilt_signs


def test_errors():
    kp = keypoints()
    with pytest.raises(ValueError, match="unknown fold 'collar'"):
        fold_spec("collar", kp)
    partial = {k: v for k, v in kp.items() if k != "armpit_left"}
    with pytest.raises(ValueError, match="missing: armpit_left"):
        fold_spec("left_sleeve", partial)
    fold_spec("right_sleeve", partial)  # the right sleeve does not need it
    with pytest.raises(ValueError, match="missing: shoulder_left, shoulder_right"):
        fold_spec("middle", {k: v for k, v in kp.items() if not k.startswith("shoulder")})
    with pytest.raises(ValueError, match="'bottom_right' must be finite"):
        fold_spec("right_side", {**kp, "bottom_right": np.array([np.nan, 0, 0])})
    with pytest.raises(ValueError, match="must be finite"):
        fold_spec("middle", {**kp, "shoulder_left": np.array([0, np.inf, 0])})
    with pytest.raises(ValueError, match="3-vector"):
        fold_spec("middle", {**kp, "shoulder_left": np.array([0, 0])})
    with pytest.raises(ValueError, match="'bottom_left' and 'bottom_right' coincide"):
        fold_spec("middle", {**kp, "bottom_left": kp["bottom_right"]})
    with pytest.raises(ValueError, match="end_angle_deg"):
        fold_spec("middle", kp, end_angle_deg=0.0)
    with pytest.raises(ValueError, match="end_height"):
        fold_spec("middle", kp, end_height=-0.01)


def test_gripper_on_fold_line_raises():
    kp = keypoints()
    spec = fold_spec("right_sleeve", kp)
    n = spec.normal
    on_line = spec.line_point + 0.3 * spec.line_direction + 0.0004 * n  # 0.4 mm from the line
    bad = {**kp, "sleeve_top_right": on_line + 0.05 * n, "sleeve_bottom_right": on_line - 0.05 * n}
    with pytest.raises(ValueError, match=r"gripper 0 .* mm from the fold line"):
        fold_spec("right_sleeve", bad)


def test_foldspec_validation():
    spec = fold_spec("middle", keypoints())
    args = dict(name="x", line_point=spec.line_point, line_direction=spec.line_direction,
                start_poses=spec.start_poses, end_poses=spec.end_poses, tilt_signs=spec.tilt_signs,
                layer_offset_factor=4.0)
    FoldSpec(**args)
    with pytest.raises(ValueError, match="horizontal"):
        FoldSpec(**{**args, "line_direction": np.array([1.0, 0.0, 0.5])})
    with pytest.raises(ValueError, match="counts differ"):
        FoldSpec(**{**args, "tilt_signs": (1.0,)})
    with pytest.raises(ValueError, match=r"\+1 or -1"):
        FoldSpec(**{**args, "tilt_signs": (1.0, 0.5)})
    with pytest.raises(ValueError, match="layer_offset_factor"):
        FoldSpec(**{**args, "layer_offset_factor": 0.0})
    with pytest.raises(ValueError, match="both sides"):
        FoldSpec(**{**args, "start_poses": (spec.start_poses[0], spec.end_poses[1])})
    p = Pose(spec.line_point + [0.0, 0.0005, 0.0], [0, 0, 0, 1])
    with pytest.raises(ValueError, match="from the fold line"):
        FoldSpec(**{**args, "start_poses": (spec.start_poses[0], p)})


def test_all_shapes_plan_every_fold():
    for k in SHAPES:
        kp = keypoints(k)
        for name in FOLD_SEQUENCE:
            spec = fold_spec(name, kp)
            assert all(spec.side_of_line(p.position) > 0.01 for p in spec.start_poses)


def test_folds_done_keeps_the_flat_lines_and_grasps():
    """With the folds done named, visible keypoints (hem corners on the side creases, a
    quarter of the flat hem width in) give the flat shirt's side line and middle grasps."""
    kp = keypoints()
    hem_y = kp["bottom_left"][1]
    left_done = {**kp, "bottom_left": np.array([-W / 4, hem_y, 0.0])}
    spec = fold_spec("right_side", left_done, folds_done=["left_sleeve", "right_sleeve", "left_side"])
    assert spec.line_point[0] == pytest.approx(W / 4)
    np.testing.assert_allclose([p.matrix for p in spec.start_poses],
                               [p.matrix for p in fold_spec("right_side", kp).start_poses], atol=1e-12)
    assert fold_spec("right_side", left_done).line_point[0] == pytest.approx(W / 2 - 3 * W / 16)  # not told
    both = {**left_done, "bottom_right": np.array([W / 4, hem_y, 0.0])}
    spec = fold_spec("middle", both, folds_done=["left_side", "right_side"])
    np.testing.assert_allclose([p.position for p in spec.start_poses], [[-W / 4, hem_y, 0], [W / 4, hem_y, 0]],
                               atol=1e-12)
    one = fold_spec("middle", left_done, folds_done=["left_side"])
    np.testing.assert_allclose([p.position for p in one.start_poses], [[-W / 4, hem_y, 0], [W / 4, hem_y, 0]],
                               atol=1e-12)
    with pytest.raises(ValueError, match="unknown folds in folds_done: collar"):
        fold_spec("middle", kp, folds_done=["collar"])


def test_fold_names_and_their_uses_come_from_the_registry():
    from clothfold_ros.folding import FOLD_KINDS, FOLDS, fold_type
    from clothfold_ros.lookup.scenario import STAGE_OF_FOLD

    assert FOLD_NAMES == tuple(FOLDS) and all(f.kind in FOLD_KINDS for f in FOLDS.values())
    assert STAGE_OF_FOLD == {n: f.stage_group for n, f in FOLDS.items()}
    assert {n: fold_type(n) for n in FOLD_NAMES} == {n: f.kind for n, f in FOLDS.items()}


def test_hem_corners_folded_onto_the_middle_are_refused_and_the_sweep_plans_from_the_flat_shirt():
    """After both side folds the material hem corners lie a centimetre apart near the middle: a
    middle fold planned from them put both grippers at the centre. fold_spec refuses a flat hem
    narrower than MIN_HEM_WIDTH, so the sweep's spec_for takes the flat shirt's keypoints (the
    study's line and grasps, a quarter of the width in from each side)."""
    from clothfold_ros.folding import MIN_HEM_WIDTH
    from clothfold_ros.lookup.scenario import spec_for

    flat = keypoints()
    folded = dict(flat)
    mid = (flat["bottom_left"] + flat["bottom_right"]) / 2
    folded["bottom_left"], folded["bottom_right"] = mid - [0.006, 0.0, 0.0], mid + [0.006, 0.0, 0.0]
    with pytest.raises(ValueError, match="hem corners 12.0 mm apart"):
        fold_spec("middle", folded, 170.0)
    spec, note = spec_for("middle", folded, flat, 170.0)
    assert note.startswith("spec from the flat shirt's keypoints") and "hem corners" in note
    width = np.linalg.norm(flat["bottom_right"] - flat["bottom_left"])
    xs = sorted(float((p.position - mid) @ (flat["bottom_right"] - flat["bottom_left"]) / width)
                for p in spec.start_poses)
    assert xs == pytest.approx([-width / 4, width / 4], abs=1e-9)
    assert width > 3 * MIN_HEM_WIDTH  # the shirts' hems are far from the limit
    # the visible hem after both side folds (half the flat width) still plans with folds_done
    vis = dict(flat)
    vis["bottom_left"], vis["bottom_right"] = mid - [width / 4, 0, 0], mid + [width / 4, 0, 0]
    fold_spec("middle", vis, 170.0, folds_done=["left_sleeve", "right_sleeve", "left_side", "right_side"])
