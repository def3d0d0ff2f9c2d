"""Folded-state (visible) keypoints on ideally folded shirts (loss.fold_target composed
stage by stage), and fold specs planned from them."""
from __future__ import annotations

import numpy as np
import pytest
import shapely
import shapely.affinity
from scipy.spatial.transform import Rotation

from clothfold_ros.folding import FOLD_SEQUENCE, body_length, fold_spec
from clothfold_ros.garment import KEYPOINT_NAMES, SHAPES, make_shirt, shirt_outline
from clothfold_ros.loss import fold_target
from clothfold_ros.perception.visible import FoldLine, keypoint_locations, visible_keypoints

T = 3e-4  # m, thickness used for the layer offsets


def stages(shape: int = 1, max_area: float = 5e-4):
    """[(folds done, vertices, specs)] after 0..5 folds, every stage planned from the
    visible keypoints of the previous one."""
    g = make_shirt(shape, max_area=max_area)
    v, specs, out = g.vertices.copy(), [], []
    for name in FOLD_SEQUENCE:
        out.append((tuple(s.name for s in specs), v, list(specs)))
        spec = fold_spec(name, visible_keypoints(g, v, specs), folds_done=[s.name for s in specs])
        specs.append(spec)
        v = fold_target(v, spec, T)
    out.append((tuple(s.name for s in specs), v, list(specs)))
    return g, out


def silhouette(g, specs) -> shapely.Polygon:
    """Top-view outline of the ideally folded flat outline polygon (shapely, no mesh)."""
    geom = shapely.Polygon(shirt_outline(g.shape))
    for s in specs:
        p, n, d = s.line_point[:2], s.normal[:2], s.line_direction[:2]
        big = 10.0
        plus = shapely.Polygon([p + big * d, p + big * d + big * n, p - big * d + big * n, p - big * d])
        moved, kept = geom.intersection(plus), geom.difference(plus)
        a = np.eye(2) - 2 * np.outer(n, n)
        off = 2 * (p @ n) * n
        moved = shapely.affinity.affine_transform(moved, [a[0, 0], a[0, 1], a[1, 0], a[1, 1], off[0], off[1]])
        geom = shapely.union_all([kept, moved]).buffer(1e-9).buffer(-1e-9)
    assert geom.geom_type == "Polygon"
    return geom


def test_flat_shirt_gives_the_material_keypoints():
    g = make_shirt(1, max_area=2e-3)
    for vertices in (None, g.vertices + [0.1, -0.05, 0.002]):
        kp, mat = visible_keypoints(g, vertices), g.keypoints(vertices)
        assert list(kp) == list(KEYPOINT_NAMES)
        for n in KEYPOINT_NAMES:
            np.testing.assert_array_equal(kp[n], mat[n])


def test_after_one_sleeve():
    g, st = stages(1)
    _, v, specs = st[1]
    kp, mat = visible_keypoints(g, v, specs), g.keypoints(v)
    for n in ("sleeve_top_left", "sleeve_bottom_left"):  # where the folded cuff now lies
        np.testing.assert_array_equal(kp[n], mat[n])
        assert specs[0].side_of_line(kp[n]) < -0.05  # folded over onto the body
    right = [n for n in KEYPOINT_NAMES if n.endswith("right") or n == "neck_middle"]
    for n in right + ["armpit_left", "bottom_left"]:
        np.testing.assert_array_equal(kp[n], mat[n])
    # the shoulder's material point was folded away: its keypoint is the folded outline's corner on the line
    assert abs(specs[0].side_of_line(kp["shoulder_left"])) < 1e-3
    assert silhouette(g, specs).exterior.distance(shapely.Point(kp["shoulder_left"][:2])) < 1e-3
    assert np.linalg.norm(kp["shoulder_left"] - mat["shoulder_left"]) > 0.05


def test_after_both_sleeves_is_symmetric():
    g, st = stages(1)
    _, v, specs = st[2]
    kp = visible_keypoints(g, v, specs)
    mirror = np.array([-1.0, 1.0, 1.0])
    for n in KEYPOINT_NAMES:
        m = n.replace("left", "@").replace("right", "left").replace("@", "right")
        np.testing.assert_allclose(kp[n][:2], (kp[m] * mirror)[:2], atol=1e-9)


@pytest.mark.parametrize("shape", sorted(SHAPES))
def test_after_both_sides_hem_corners_are_the_folded_outline_corners(shape):
    g, st = stages(shape)
    _, v, specs = st[4]
    w = g.shape.bottom_width * g.shape.scale
    hem_y = -0.5 * g.shape.scale
    kp, mat = visible_keypoints(g, v, specs), g.keypoints(v)
    np.testing.assert_allclose(kp["bottom_left"][:2], [-w / 4, hem_y], atol=1e-9)
    np.testing.assert_allclose(kp["bottom_right"][:2], [w / 4, hem_y], atol=1e-9)
    sil = silhouette(g, specs)
    for n in ("bottom_left", "bottom_right", "armpit_left", "armpit_right"):
        assert sil.exterior.distance(shapely.Point(kp[n][:2])) < 1e-6, n  # on the visible outline
    # material hem corners coincide near the centre line: the old middle fold could not be planned
    assert np.linalg.norm((mat["bottom_left"] - mat["bottom_right"])[:2]) < 0.01
    with pytest.raises(ValueError, match="coincide"):
        fold_spec("middle", mat)
    # from the visible keypoints it grasps where the study did: a quarter of the flat hem width in
    flat = fold_spec("middle", g.keypoints())
    spec = fold_spec("middle", kp, folds_done=st[4][0])
    for a, b in zip(flat.start_poses, spec.start_poses):
        np.testing.assert_allclose(a.position[:2], b.position[:2], atol=1e-9)
        np.testing.assert_allclose(a.matrix, b.matrix, atol=1e-9)


@pytest.mark.parametrize("shape", sorted(SHAPES))
def test_each_stage_plans_like_the_study(shape):
    """Sleeve and side folds planned from the visible keypoints of the ideally folded shirt
    equal the study's (planned from the flat keypoints); so do the middle grasps."""
    g, st = stages(shape)
    flat = g.keypoints()
    for (done, v, specs), name in zip(st, FOLD_SEQUENCE):
        a, b = fold_spec(name, flat), fold_spec(name, visible_keypoints(g, v, specs), folds_done=done)
        for pa, pb in zip(a.start_poses, b.start_poses):
            np.testing.assert_allclose(pa.position[:2], pb.position[:2], atol=1e-9)
        if name != "middle":
            for pa, pb in zip(a.end_poses, b.end_poses):
                np.testing.assert_allclose(pa.position, pb.position, atol=1e-9)
            assert b.side_of_line(a.line_point) == pytest.approx(0, abs=1e-9)
            assert abs(a.line_direction @ b.line_direction) == pytest.approx(1)
    # without the flat body length the middle line is halfway between the hem and the visible
    # shoulder corners, above the study's; with it, on the study's line
    done, v, specs = st[4]
    study = fold_spec("middle", flat)
    kp = visible_keypoints(g, v, specs)
    b = fold_spec("middle", kp, folds_done=done)
    assert 0.01 < b.line_point[1] - study.line_point[1] < 0.04
    c = fold_spec("middle", kp, folds_done=done, body_length=body_length(flat))
    assert study.side_of_line(c.line_point) == pytest.approx(0, abs=1e-9)
    assert abs(study.line_direction @ c.line_direction) == pytest.approx(1)
    for pa, pc in zip(study.end_poses, c.end_poses):  # the located hem corners' tiny skew: 20 um
        np.testing.assert_allclose(pa.position, pc.position, atol=1e-4)


def test_body_length_refuses_shoulders_below_the_hem():
    g, _ = stages(1)
    kp = g.keypoints()
    assert 0.3 < body_length(kp) < 1.0
    with pytest.raises(ValueError, match="beyond"):
        body_length({**kp, "shoulder_left": kp["bottom_left"] - [0, 0.1, 0], "shoulder_right": kp["bottom_right"] - [0, 0.1, 0]})
    with pytest.raises(ValueError, match="body_length"):
        fold_spec("middle", kp, body_length=float("nan"))


def test_moved_shirt_moves_its_visible_keypoints():
    g, st = stages(1)
    rot, shift = Rotation.from_euler("z", 25, degrees=True), np.array([0.2, -0.1, 0.0])
    moved = make_shirt(1, max_area=5e-4)
    moved.vertices = rot.apply(g.vertices) + shift
    v, specs = moved.vertices.copy(), []
    for name in FOLD_SEQUENCE[:4]:
        spec = fold_spec(name, visible_keypoints(moved, v, specs), folds_done=[s.name for s in specs])
        specs.append(spec)
        v = fold_target(v, spec, T)
    _, v0, specs0 = st[4]
    kp, kp0 = visible_keypoints(moved, v, specs), visible_keypoints(g, v0, specs0)
    for n in KEYPOINT_NAMES:
        np.testing.assert_allclose(kp[n], rot.apply(kp0[n]) + shift, atol=1e-6)


def test_perturbed_cloth_keeps_keypoints_close():
    """A slightly wrinkled / shifted folded cloth (as a simulator gives) moves the visible
    keypoints by a few times as much as the cloth."""
    g, st = stages(1)
    _, v, specs = st[4]
    rng = np.random.default_rng(0)
    noisy = v + rng.normal(0, 1e-3, v.shape)
    a, b = visible_keypoints(g, v, specs), visible_keypoints(g, noisy, specs)
    err = [np.linalg.norm(a[n] - b[n]) for n in KEYPOINT_NAMES]
    assert max(err) < 6e-3  # the vertex noise is 1.7 mm (norm); the fit extrapolates to the crease


def test_bad_inputs():
    g = make_shirt(1, max_area=2e-3)
    with pytest.raises(ValueError, match="shape"):
        visible_keypoints(g, g.vertices[:-1])
    bad = g.vertices.copy()
    bad[3, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        visible_keypoints(g, bad)
    with pytest.raises(ValueError, match="outline"):
        keypoint_locations(np.zeros((5, 2)), [])
    with pytest.raises(TypeError):
        visible_keypoints(g, None, ["left_sleeve"])


def test_a_crease_inside_the_fold_line_moves_the_crease_keypoints_only():
    """A real fold's visible edge can lie inside its line (the bulge): crease-made keypoints
    (hem corner, armpit) follow the crease, mirrored ones (the cuff) follow the line."""
    g = make_shirt(1, max_area=2e-3)
    outline = g.vertices[:13, :2]
    spec = fold_spec("left_side", g.keypoints())
    ideal = FoldLine.of(spec)
    bulged = FoldLine(ideal.name, ideal.point, ideal.normal, crease=0.02)
    a, b = keypoint_locations(outline, [ideal]), keypoint_locations(outline, [bulged])
    edge = ideal.point[0] + 0.02  # the crease's x (the left side folds over to +x)
    for k, n in enumerate(KEYPOINT_NAMES):
        if n.startswith("sleeve_") or outline[k, 0] > edge:  # mirrored or untouched: as for the ideal fold
            np.testing.assert_allclose(b[k], a[k], atol=1e-12)
        else:  # bottom, armpit, shoulder, neck of the left side: on the crease, at their height
            np.testing.assert_allclose(b[k], [edge, outline[k, 1]], atol=1e-12)
    assert {"bottom_left", "armpit_left"} <= {n for k, n in enumerate(KEYPOINT_NAMES) if b[k, 0] == edge}


def test_the_keypoint_rules_are_the_fold_kinds_registry(monkeypatch):
    """visible.py holds no per-type branches: a fold type's rules are its FOLD_KINDS entry."""
    import dataclasses

    from clothfold_ros import folding

    g = make_shirt(1, max_area=5e-3)
    flat = np.array([g.keypoints()[n][:2] for n in KEYPOINT_NAMES])
    spec = fold_spec("left_sleeve", g.keypoints())
    moved = keypoint_locations(flat, [spec])
    i = KEYPOINT_NAMES.index("shoulder_left")
    assert not np.allclose(moved[i], flat[i])  # the sleeve's outline corner rule moved the shoulder
    kinds = dict(folding.FOLD_KINDS)
    kinds["sleeve"] = dataclasses.replace(kinds["sleeve"], outline_corners=())
    monkeypatch.setattr(folding, "FOLD_KINDS", kinds)
    import clothfold_ros.perception.visible as visible

    monkeypatch.setattr(visible, "FOLD_KINDS", kinds)
    projected = keypoint_locations(flat, [spec])
    assert not np.allclose(projected[i], moved[i])  # without it: projected onto the fold line
    kinds["sleeve"] = dataclasses.replace(kinds["sleeve"], keeps_keypoints=True)
    np.testing.assert_allclose(keypoint_locations(flat, [spec]), flat)
