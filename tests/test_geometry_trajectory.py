"""Two-parameter trajectories (docs/method.md section 6)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from clothfold_ros.folding import fold_spec
from clothfold_ros.garment import KEYPOINT_NAMES, shirt_outline
from clothfold_ros.pose import Pose
from clothfold_ros.trajectory import FoldTrajectory, GripperPath, bezier_control_point, fan, min_jerk

# start 0.5 m from a fold line along y through the origin, end mirrored, all at z = 0.1
S, E = np.array([0.5, 0.0, 0.1]), np.array([-0.4, 0.0, 0.1])
LINE_P, LINE_D = np.array([0.0, 0.3, 0.1]), np.array([0.0, 1.0, 0.0])


def sleeve_spec():
    kp = {n: np.array([x, y, 0.0]) for n, (x, y) in zip(KEYPOINT_NAMES, shirt_outline(1))}
    return fold_spec("right_sleeve", kp), fold_spec("middle", kp)


def test_fan():
    f = fan()
    assert f.shape == (134, 2)
    heights = np.unique(f[:, 0])
    np.testing.assert_allclose(heights, np.linspace(0.1, 1.0, 14))
    counts = [int(np.sum(f[:, 0] == h)) for h in heights]
    assert counts == [2, 3, 4, 5, 6, 8, 9, 10, 11, 13, 14, 15, 16, 18]
    assert sum(counts) == 134
    for h, n in zip(heights, counts):
        np.testing.assert_allclose(f[f[:, 0] == h, 1], np.linspace(60, 0, n))  # 60 down to 0, ends included
    assert fan(2).shape == (2 + 18, 2)


def test_control_point_without_tilt():
    c = bezier_control_point(S, E, LINE_P, LINE_D, 0.6, 0.0)
    np.testing.assert_allclose(c, [0.0, 0.0, 0.1 + 2 * 0.6 * 0.5], atol=1e-12)  # m raised by 2 h d
    path = GripperPath(Pose(S, [0, 0, 0, 1]), Pose(E, [0, 0, 0, 1]), c, 4.0)
    np.testing.assert_allclose(path.curve(0.5), (S + E) / 4 + c / 2, atol=1e-12)
    z = path.curve(np.linspace(0, 1, 2001))[:, 2]
    assert z.max() == pytest.approx(0.1 + 0.6 * 0.5)  # apex h d above the start height


def test_tilt_rotates_about_start_end_axis():
    c0 = bezier_control_point(S, E, LINE_P, LINE_D, 0.6, 0.0)
    c = bezier_control_point(S, E, LINE_P, LINE_D, 0.6, 30.0, 1.0)
    # axis -x through S: the raised offset (0, 0, 0.6) turns toward +y by 30 deg
    np.testing.assert_allclose(c, [0.0, 0.6 * 0.5, 0.1 + 0.6 * math.cos(math.radians(30))], atol=1e-12)
    cm = bezier_control_point(S, E, LINE_P, LINE_D, 0.6, 30.0, -1.0)
    np.testing.assert_allclose(cm, c * [1, -1, 1], atol=1e-12)  # the other sign mirrors it
    # general case: |c - s| and the component along (e - s) are kept, the rest turns by the tilt
    s, e = np.array([0.2, 0.1, 0.0]), np.array([-0.1, 0.3, 0.05])
    k = (e - s) / np.linalg.norm(e - s)
    a = bezier_control_point(s, e, LINE_P, [1.0, 1.0, 0.0], 0.8, 0.0) - s
    b = bezier_control_point(s, e, LINE_P, [1.0, 1.0, 0.0], 0.8, 50.0) - s
    assert np.linalg.norm(a) == pytest.approx(np.linalg.norm(b)) and a @ k == pytest.approx(b @ k)
    ap, bp = a - (a @ k) * k, b - (b @ k) * k
    assert math.degrees(math.atan2(np.cross(ap, bp) @ k, ap @ bp)) == pytest.approx(50.0)


def test_min_jerk_profile():
    assert min_jerk(0.0) == 0 and min_jerk(1.0) == 1 and min_jerk(0.5) == pytest.approx(0.5)
    for d in (1, 2):
        assert min_jerk(0.0, d) == 0 and min_jerk(1.0, d) == 0
    tau = np.linspace(0, 1, 10001)
    np.testing.assert_allclose(np.gradient(min_jerk(tau), tau)[1:-1], min_jerk(tau, 1)[1:-1], atol=1e-6)
    np.testing.assert_allclose(np.gradient(min_jerk(tau, 1), tau)[1:-1], min_jerk(tau, 2)[1:-1], atol=1e-5)
    assert min_jerk(tau, 1).max() == pytest.approx(1.875)


@pytest.fixture
def path():
    spec, _ = sleeve_spec()
    a, b = spec.start_poses[0], spec.end_poses[0]
    c = bezier_control_point(a.position, b.position, spec.line_point, spec.line_direction, 0.7, 20.0,
                             spec.tilt_signs[0])
    return GripperPath(a, b, c, 4.0)


def test_path_ends_and_clamping(path):
    np.testing.assert_allclose(path.position(0.0), path.start.position, atol=1e-12)
    np.testing.assert_allclose(path.position(4.0), path.end.position, atol=1e-12)
    np.testing.assert_allclose(path.position(-1.0), path.start.position, atol=1e-12)
    np.testing.assert_allclose(path.position(9.0), path.end.position, atol=1e-12)
    assert path.position(np.array([0.0, 1.0, 2.0])).shape == (3, 3)
    np.testing.assert_allclose(path.velocity(np.array([0.0, 4.0, -1.0, 5.0])), 0.0, atol=1e-12)


def test_min_jerk_along_arc_length(path):
    t = np.linspace(0, 4, 4001)
    p = path.position(t)
    travelled = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    assert travelled[-1] == pytest.approx(path.length, rel=1e-5)
    np.testing.assert_allclose(travelled, path.length * min_jerk(t / 4.0), atol=1e-5)
    # analytic length of a quadratic Bezier by dense sampling, independent of the path's own table
    u = np.linspace(0, 1, 200001)
    assert path.length == pytest.approx(np.sum(np.linalg.norm(np.diff(path.curve(u), axis=0), axis=1)), rel=1e-7)
    speed = np.linalg.norm(path.velocity(t), axis=1)
    assert path.peak_speed == pytest.approx(1.875 * path.length / 4.0)
    assert speed.max() == pytest.approx(path.peak_speed, rel=1e-6)
    np.testing.assert_allclose(speed[1:-1], np.linalg.norm(np.gradient(p, t, axis=0), axis=1)[1:-1], rtol=2e-3,
                               atol=1e-4)
    # zero acceleration at both ends: speed grows like t^2
    dt = 1e-3
    assert np.linalg.norm(path.velocity(dt)) < 1e-4 and np.linalg.norm(path.velocity(4 - dt)) < 1e-4


def test_straight_path_length():
    s, e = np.array([0.0, 0.0, 0.0]), np.array([0.3, 0.4, 0.0])
    p = GripperPath(Pose(s, [0, 0, 0, 1]), Pose(e, [0, 0, 0, 1]), (s + e) / 2, 2.0)
    assert p.length == pytest.approx(0.5, rel=1e-12)
    np.testing.assert_allclose(p.position(1.0), (s + e) / 2, atol=1e-9)  # half time = half way


def test_orientation_slerp(path):
    q0, q1 = path.pose(0.0).quaternion, path.pose(4.0).quaternion
    assert abs(q0 @ path.start.quaternion) == pytest.approx(1.0)
    assert abs(q1 @ path.end.quaternion) == pytest.approx(1.0)
    half = Rotation.from_quat(path.pose(2.0).quaternion)  # progress 0.5 at T / 2
    to_mid = (half * path.start.rotation.inv()).magnitude()
    total = (path.end.rotation * path.start.rotation.inv()).magnitude()
    assert to_mid == pytest.approx(total / 2)
    t1 = 1.0
    frac = min_jerk(t1 / 4.0)
    part = (Rotation.from_quat(path.pose(t1).quaternion) * path.start.rotation.inv()).magnitude()
    assert part == pytest.approx(frac * total)


def test_fold_trajectory_sampling():
    _, middle = sleeve_spec()
    tr = FoldTrajectory(middle, 0.5, 40.0, duration=4.0)
    assert len(tr.paths) == 2
    poses = tr.poses_at(0.0)
    assert len(poses) == 2
    for p, s in zip(poses, middle.start_poses):
        np.testing.assert_allclose(p.position, s.position, atol=1e-12)
    times, pos, quat = tr.sample(25.0)
    np.testing.assert_array_equal(times, np.arange(101) / 25.0)
    assert times[0] == 0.0 and times[-1] == 4.0
    assert pos.shape == (101, 2, 3) and quat.shape == (101, 2, 4)
    np.testing.assert_allclose(pos[-1], [e.position for e in middle.end_poses], atol=1e-12)
    np.testing.assert_allclose(pos[50], [p.position for p in tr.poses_at(2.0)], atol=1e-12)
    # the two arcs bow away from each other
    assert pos[50, 0, 0] < middle.start_poses[0].position[0] and pos[50, 1, 0] > middle.start_poses[1].position[0]
    odd = FoldTrajectory(middle, 0.5, 40.0, duration=1.1).sample(2.0)[0]
    np.testing.assert_allclose(odd, [0.0, 0.5, 1.0, 1.1])


def test_default_sleeve_peak_speed_matches_spec():
    spec, _ = sleeve_spec()
    peak = max(FoldTrajectory(spec, h, t).paths[0].peak_speed for h, t in fan())
    assert peak == pytest.approx(0.65, abs=0.02)  # docs/method.md section 6: about 0.65 m/s


@pytest.mark.parametrize("h, tilt, duration, message", [
    (0.0, 10.0, 4.0, "height ratio"),
    (1.6, 10.0, 4.0, "height ratio"),
    (float("nan"), 10.0, 4.0, "height ratio"),
    (0.5, -1.0, 4.0, "tilt"),
    (0.5, 91.0, 4.0, "tilt"),
    (0.5, float("inf"), 4.0, "tilt"),
    (0.5, 10.0, 0.0, "duration"),
    (0.5, 10.0, float("nan"), "duration"),
])
def test_bad_parameters(h, tilt, duration, message):
    spec, _ = sleeve_spec()
    with pytest.raises(ValueError, match=message):
        FoldTrajectory(spec, h, tilt, duration)


def test_bad_inputs():
    spec, _ = sleeve_spec()
    tr = FoldTrajectory(spec, 1.5, 90.0)  # the limits themselves are allowed
    with pytest.raises(ValueError, match="rate"):
        tr.sample(0.0)
    with pytest.raises(ValueError, match="non-zero"):
        bezier_control_point(S, S, LINE_P, LINE_D, 0.5, 0.0)
    with pytest.raises(ValueError, match="finite"):
        bezier_control_point(S, E, [np.nan, 0, 0], LINE_D, 0.5, 0.0)
    with pytest.raises(ValueError, match="duration"):
        GripperPath(spec.start_poses[0], spec.end_poses[0], S, -1.0)
    with pytest.raises(ValueError, match="control point"):
        GripperPath(spec.start_poses[0], spec.end_poses[0], [np.nan, 0, 0], 1.0)


def test_path_below_the_table_top_is_refused_with_where():
    """The table is z = 0: a path whose curve dips below it is refused when built, with the depth
    and the Bezier parameter; the analytic lowest point matches a dense sampling of the curve."""
    q = [0, 0, 0, 1]
    a, b = Pose([0.0, 0.0, 0.01], q), Pose([0.2, 0.0, 0.01], q)
    with pytest.raises(ValueError, match=r"z = -4\.000 mm at Bezier parameter 0\.500: below the table top"):
        GripperPath(a, b, [0.1, 0.0, -0.018], 4.0)  # vertex z(0.5) = 0.005 - 0.009 = -4 mm
    with pytest.raises(ValueError, match=r"z = -50\.000 mm at Bezier parameter 0\.000"):
        GripperPath(Pose([0.0, 0.0, -0.05], q), b, [0.1, 0.0, 0.2], 4.0)  # the start itself
    GripperPath(Pose([0.0, 0.0, 0.0], q), Pose([0.2, 0.0, 0.0], q), [0.1, 0.0, 0.0], 4.0)  # on the table: allowed
    for control in ([0.1, 0.0, 0.3], [0.1, 0.05, -0.01], [0.1, 0.0, 0.004]):
        path = GripperPath(a, b, control, 4.0)
        u, z = path.lowest_point()
        dense = path.curve(np.linspace(0.0, 1.0, 100001))[:, 2]
        assert z == pytest.approx(dense.min(), abs=1e-12) and path.curve(u)[2] == pytest.approx(z)


def test_every_fan_point_stays_above_the_table():
    """The search space itself never reaches below the table (both tilt signs, sleeve and middle)."""
    for spec in sleeve_spec():
        for h, tilt in fan():
            for path in FoldTrajectory(spec, h, tilt).paths:
                assert path.lowest_point()[1] >= -1e-12, (spec.name, h, tilt)
