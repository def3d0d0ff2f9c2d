"""Shirt outline and mesh (docs/method.md section 1)."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from clothfold_ros.garment import KEYPOINT_NAMES, SHAPES, ShirtShape, make_shirt, shirt_outline

COARSE = 1e-3  # m^2


@pytest.fixture(scope="module")
def coarse():
    return make_shirt(1, max_area=COARSE, z=0.01)


def test_keypoint_names_in_outline_order():
    assert KEYPOINT_NAMES == (
        "bottom_right", "armpit_right", "sleeve_bottom_right", "sleeve_top_right", "shoulder_right",
        "neck_right", "neck_middle", "neck_left", "shoulder_left", "sleeve_top_left",
        "sleeve_bottom_left", "armpit_left", "bottom_left")


def test_shapes_table():
    assert SHAPES[1] == ShirtShape(0.65, 0.32, 0.08, 0.62, 0.90, 0.28, 0.18, 0.76, -3.0, 0.635)
    assert SHAPES[2] == ShirtShape(0.65, 0.32, 0.08, 0.62, 0.94, 0.28, 0.18, 0.76, 30.0, 0.635)
    assert SHAPES[3] == ShirtShape(0.75, 0.25, 0.10, 0.68, 0.95, 0.30, 0.25, 0.22, 5.0, 0.635)


def test_shape1_outline_hand_computed():
    # B = sqrt(0.28^2 - 0.015^2) = 0.2795980; armpit y = 0.9 - B; sleeve middle (0.3175, 0.7602010);
    # cuff offsets (0.76, -+0.09) rotated by +3 deg: (0.7636683, -0.0501021), (0.7542479, 0.1296526).
    right = {
        "bottom_right": (0.325, 0.0),
        "armpit_right": (0.325, 0.6204020),
        "sleeve_bottom_right": (1.0811683, 0.7100989),
        "sleeve_top_right": (1.0717479, 0.8898536),
        "shoulder_right": (0.31, 0.9),
        "neck_right": (0.16, 1.0),
        "neck_middle": (0.0, 0.92),
    }
    out = shirt_outline(1)
    assert out.shape == (13, 2)
    for name, (x, y) in right.items():
        expected = np.array([x, y - 0.5]) * 0.635
        np.testing.assert_allclose(out[KEYPOINT_NAMES.index(name)], expected, atol=1e-6, err_msg=name)
        mirror = KEYPOINT_NAMES.index(name.replace("right", "left"))
        np.testing.assert_allclose(out[mirror], expected * [-1, 1], atol=1e-6, err_msg=name)


@pytest.mark.parametrize("k", [1, 2, 3])
def test_sleeve_geometry(k):
    s, out = SHAPES[k], shirt_outline(k)
    kp = dict(zip(KEYPOINT_NAMES, out))
    for side, sx in (("right", 1.0), ("left", -1.0)):
        assert np.linalg.norm(kp[f"shoulder_{side}"] - kp[f"armpit_{side}"]) == pytest.approx(
            s.sleeve_width_start * s.scale, rel=1e-12)
        top, bottom = kp[f"sleeve_top_{side}"], kp[f"sleeve_bottom_{side}"]
        assert np.linalg.norm(top - bottom) == pytest.approx(s.sleeve_width_end * s.scale, rel=1e-12)
        middle = (kp[f"shoulder_{side}"] + kp[f"armpit_{side}"]) / 2
        cuff = (top + bottom) / 2
        assert np.linalg.norm(cuff - middle) == pytest.approx(s.sleeve_length * s.scale, rel=1e-12)
        # positive angle points the sleeve down, on both sides
        angle = math.degrees(math.atan2(-(cuff - middle)[1], sx * (cuff - middle)[0]))
        assert angle == pytest.approx(s.sleeve_angle_deg, abs=1e-9)
    assert kp["neck_left"][1] - kp["bottom_left"][1] == pytest.approx(s.scale)  # height = scale


def test_mesh_keeps_outline_as_first_vertices(coarse):
    np.testing.assert_array_equal(coarse.vertices[:13, :2], shirt_outline(1))
    assert coarse.keypoint_ids == {name: i for i, name in enumerate(KEYPOINT_NAMES)}
    assert coarse.vertices.dtype == np.float64 and coarse.triangles.dtype == np.int64
    assert np.all(coarse.vertices[:, 2] == 0.01)
    kp = coarse.keypoints()
    np.testing.assert_array_equal(kp["armpit_left"], coarse.vertices[11])


def test_mesh_is_valid(coarse):
    v, t = coarse.vertices, coarse.triangles
    a, b, c = v[t[:, 0], :2], v[t[:, 1], :2], v[t[:, 2], :2]
    area = 0.5 * ((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])
    assert np.all(area > 0)  # counter-clockwise seen from +z
    assert area.max() <= COARSE * (1 + 1e-9)
    p = shirt_outline(1)
    polygon = 0.5 * np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])
    assert area.sum() == pytest.approx(polygon, rel=1e-12)
    assert len(np.unique(t)) == len(v)  # every vertex used
    loop = coarse.boundary_loop()
    corners = loop[loop < 13]
    np.testing.assert_array_equal(corners, np.arange(13))  # outline order along the boundary
    mesh = coarse.to_trimesh()
    assert mesh.faces.shape == t.shape and mesh.area == pytest.approx(polygon)


def test_keypoints_from_other_vertices(coarse):
    moved = coarse.vertices + [0.1, -0.2, 0.3]
    kp = coarse.keypoints(moved)
    np.testing.assert_allclose(kp["neck_middle"], coarse.vertices[6] + [0.1, -0.2, 0.3])
    with pytest.raises(ValueError, match="shape"):
        coarse.keypoints(moved[:-1])


def test_default_resolution_matches_spec():
    g = make_shirt()
    assert 5900 <= len(g.vertices) <= 6500  # "about 6.2K vertices"
    assert 11500 <= len(g.triangles) <= 12500  # "about 12K triangles"


def _bad(**kw):
    return dataclasses.replace(SHAPES[1], **kw)


@pytest.mark.parametrize("kw, message", [
    ({"neck_width": float("nan")}, "neck_width must be finite"),
    ({"scale": float("inf")}, "scale must be finite"),
    ({"sleeve_width_start": 0.015}, "armpit is undefined"),
    ({"sleeve_width_start": 0.01}, "armpit is undefined"),
    ({"bottom_width": -0.1}, "bottom_width must be > 0"),
    ({"scale": 0.0}, "scale must be > 0"),
    ({"neck_width": 0.7}, "neck_width"),
    ({"neck_depth": -0.1}, "neck_depth"),
    ({"shoulder_height": 1.2}, "shoulder_height"),
    ({"shoulder_height": 0.2}, "armpit lies below the hem"),
    ({"sleeve_angle_deg": 89.0}, "self-intersects"),
    ({"sleeve_angle_deg": 95.0}, "sleeve_angle_deg"),
    ({"sleeve_length": "long"}, "must be a number"),
])
def test_bad_shapes_raise(kw, message):
    with pytest.raises(ValueError, match=message):
        _bad(**kw)


def test_bad_make_shirt_arguments():
    with pytest.raises(ValueError, match="unknown shirt shape"):
        make_shirt(4)
    with pytest.raises(ValueError, match="max_area"):
        make_shirt(1, max_area=0.0)
    with pytest.raises(ValueError, match="max_area"):
        make_shirt(1, max_area=float("nan"))
    with pytest.raises(ValueError, match="z must be finite"):
        make_shirt(1, max_area=COARSE, z=float("nan"))


def test_cli_shirt_writes_png(tmp_path, capsys):
    from clothfold_ros.cli import main

    out = tmp_path / "shirt.png"
    assert main(["shirt", "--shape", "3", "--fold", "right_sleeve", "--out", str(out), "--max-area", "0.002"]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "134 trajectories" in capsys.readouterr().out
