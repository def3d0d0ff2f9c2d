"""Two-parameter fold trajectories (docs/method.md section 6).

Frame: table frame, metres, seconds. Each gripper follows a quadratic Bezier curve from
its start to its end position, timed by a minimum-jerk profile along arc length, with
its orientation slerped by the same progress fraction.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from .folding import FoldSpec
from .pose import Pose, slerp

MAX_HEIGHT_RATIO = 1.5
MAX_TILT_DEG = 90.0
_ARC_SAMPLES = 4097  # samples of the arc-length table along the Bezier parameter
TABLE_TOLERANCE_M = 1e-6  # how far below the table top (z = 0) a gripper path may reach (rounding)


def fan(n_heights: int = 14) -> np.ndarray:
    """The search fan: (K, 2) rows of (height_ratio, tilt_deg); 134 rows for 14 heights.

    Heights linspace(0.1, 1.0, n_heights); ring h has max(2, floor(18 h)) tilts evenly
    from 60 down to 0 deg, ends included.
    """
    if n_heights < 1:
        raise ValueError(f"n_heights must be >= 1, got {n_heights}")
    rows = []
    for h in np.linspace(0.1, 1.0, n_heights):
        n = max(2, math.floor(18.0 * h + 1e-9))
        rows += [(h, t) for t in np.linspace(60.0, 0.0, n)]
    return np.asarray(rows, dtype=float)


def min_jerk(tau: np.ndarray | float, derivative: int = 0) -> np.ndarray:
    """Minimum-jerk progress f(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5 (or its 1st/2nd
    derivative in tau); tau is clamped to [0, 1]."""
    x = np.clip(np.asarray(tau, dtype=float), 0.0, 1.0)
    if derivative == 0:
        return x**3 * (10.0 - 15.0 * x + 6.0 * x**2)
    if derivative == 1:
        return 30.0 * x**2 * (1.0 - x) ** 2
    if derivative == 2:
        return 60.0 * x * (1.0 - x) * (1.0 - 2.0 * x)
    raise ValueError(f"derivative must be 0, 1 or 2, got {derivative}")


def _check_params(height_ratio: float, tilt_deg: float) -> None:
    if not (math.isfinite(height_ratio) and 0.0 < height_ratio <= MAX_HEIGHT_RATIO):
        raise ValueError(f"height ratio must be in (0, {MAX_HEIGHT_RATIO}], got {height_ratio}")
    if not (math.isfinite(tilt_deg) and 0.0 <= tilt_deg <= MAX_TILT_DEG):
        raise ValueError(f"tilt must be in [0, {MAX_TILT_DEG}] deg, got {tilt_deg}")


def bezier_control_point(
    start: np.ndarray,
    end: np.ndarray,
    line_point: np.ndarray,
    line_direction: np.ndarray,
    height_ratio: float,
    tilt_deg: float,
    tilt_sign: float = 1.0,
) -> np.ndarray:
    """Middle control point (3,) m: project start on the fold line (point m, distance d),
    raise m by 2 h d, rotate by tilt_sign * tilt about the axis through start along
    (end - start)."""
    _check_params(height_ratio, tilt_deg)
    s, e, p = (np.asarray(v, dtype=float).reshape(3) for v in (start, end, line_point))
    u = np.asarray(line_direction, dtype=float).reshape(3)
    if not all(np.all(np.isfinite(v)) for v in (s, e, p, u)):
        raise ValueError("start, end and fold line must be finite")
    if not (math.isfinite(tilt_sign) and tilt_sign != 0):
        raise ValueError(f"tilt_sign must be a finite non-zero number (its sign is used), got {tilt_sign}")
    if np.linalg.norm(u) < 1e-12 or np.linalg.norm(e - s) < 1e-12:
        raise ValueError("fold line direction and end - start must be non-zero")
    u = u / np.linalg.norm(u)
    m = p + ((s - p) @ u) * u
    c = m + np.array([0.0, 0.0, 2.0 * height_ratio * np.linalg.norm(s - m)])
    k = (e - s) / np.linalg.norm(e - s)
    rot = Rotation.from_rotvec(float(np.sign(tilt_sign)) * math.radians(tilt_deg) * k)
    return s + rot.apply(c - s)


class GripperPath:
    """Quadratic Bezier from start.position via `control` to end.position, min-jerk
    timed along arc length over `duration` s; orientation slerped by the same fraction.
    Times outside [0, duration] clamp to the ends. A path that reaches below the table top
    (z < 0 beyond TABLE_TOLERANCE_M) is refused: the table is z = 0 and a gripper cannot pass it."""

    def __init__(self, start: Pose, end: Pose, control: np.ndarray, duration: float) -> None:
        if not (math.isfinite(duration) and duration > 0):
            raise ValueError(f"duration must be > 0 s, got {duration}")
        c = np.asarray(control, dtype=float).reshape(3)
        if not np.all(np.isfinite(c)):
            raise ValueError(f"control point must be finite, got {c}")
        self.start, self.end, self.control, self.duration = start, end, c, float(duration)
        self._ctrl = np.stack([start.position, c, end.position])
        u_low, z_low = self.lowest_point()
        if z_low < -TABLE_TOLERANCE_M:
            raise ValueError(f"gripper path reaches z = {z_low * 1e3:.3f} mm at Bezier parameter {u_low:.3f}: "
                             "below the table top (z = 0)")
        u = np.linspace(0.0, 1.0, _ARC_SAMPLES)
        seg = np.linalg.norm(np.diff(self.curve(u), axis=0), axis=1)
        self._u = u
        self._arc = np.concatenate([[0.0], np.cumsum(seg)])  # m, arc length at u

    def curve(self, u: np.ndarray | float) -> np.ndarray:
        """B(u) for Bezier parameter u in [0, 1]; shape (..., 3)."""
        u = np.asarray(u, dtype=float)[..., None]
        s, c, e = self._ctrl
        return (1 - u) ** 2 * s + 2 * u * (1 - u) * c + u**2 * e

    def lowest_point(self) -> tuple[float, float]:
        """(u, z) of the curve's lowest point, u in [0, 1], z in m: the ends or the vertex of
        the quadratic z(u), whichever is lower."""
        s, c, e = self._ctrl[:, 2]
        candidates = [0.0, 1.0]
        curvature = s - 2.0 * c + e  # z''(u) / 2
        if curvature > 0.0:
            u_vertex = (s - c) / curvature
            if 0.0 < u_vertex < 1.0:
                candidates.append(float(u_vertex))
        zs = [float(self.curve(u)[2]) for u in candidates]
        k = int(np.argmin(zs))
        return candidates[k], zs[k]

    def _curve_tangent(self, u: np.ndarray) -> np.ndarray:
        s, c, e = self._ctrl
        u = u[..., None]
        return 2 * (1 - u) * (c - s) + 2 * u * (e - c)

    @property
    def length(self) -> float:
        """Arc length of the path (m)."""
        return float(self._arc[-1])

    @property
    def peak_speed(self) -> float:
        """Maximum speed (m/s) of min-jerk timing: 1.875 L / T."""
        return 1.875 * self.length / self.duration

    def progress(self, t: np.ndarray | float) -> np.ndarray:
        """Fraction of the path done at time t (s), in [0, 1]."""
        t = np.asarray(t, dtype=float)
        if not np.all(np.isfinite(t)):
            raise ValueError(f"path time must be finite, got {t}")
        return min_jerk(t / self.duration)

    def _param(self, t: np.ndarray | float) -> np.ndarray:
        return np.interp(self.progress(t) * self.length, self._arc, self._u) if self.length > 0 \
            else np.zeros_like(np.asarray(t, dtype=float))

    def position(self, t: np.ndarray | float) -> np.ndarray:
        """Position (m) at time t (s); shape (3,) or (K, 3) for K times."""
        return self.curve(self._param(t))

    def velocity(self, t: np.ndarray | float) -> np.ndarray:
        """Velocity (m/s) at time t (s): unit tangent times L f'(t/T) / T; zero outside [0, T]."""
        t = np.asarray(t, dtype=float)
        tangent = self._curve_tangent(self._param(t))
        norm = np.linalg.norm(tangent, axis=-1, keepdims=True)
        unit = np.divide(tangent, norm, out=np.zeros_like(tangent), where=norm > 1e-12)
        inside = (t >= 0) & (t <= self.duration)
        speed = np.where(inside, min_jerk(t / self.duration, 1) * self.length / self.duration, 0.0)
        return unit * speed[..., None]

    def quaternion(self, t: np.ndarray | float) -> np.ndarray:
        """Orientation (x, y, z, w) at time t (s); shape (4,) or (K, 4)."""
        return slerp(self.start, self.end, self.progress(t))

    def pose(self, t: float) -> Pose:
        """The gripper pose at time t (s)."""
        return Pose(self.position(float(t)), self.quaternion(float(t)))


class FoldTrajectory:
    """All grippers of a fold on one clock: a GripperPath each for (height_ratio,
    tilt_deg) over `duration` s."""

    def __init__(self, spec: FoldSpec, height_ratio: float, tilt_deg: float, duration: float = 4.0) -> None:
        _check_params(height_ratio, tilt_deg)
        if not (math.isfinite(duration) and duration > 0):
            raise ValueError(f"duration must be > 0 s, got {duration}")
        self.spec, self.height_ratio, self.tilt_deg, self.duration = spec, float(height_ratio), float(tilt_deg), \
            float(duration)
        self.paths: list[GripperPath] = [
            GripperPath(a, b, bezier_control_point(a.position, b.position, spec.line_point, spec.line_direction,
                                                   height_ratio, tilt_deg, sign), duration)
            for a, b, sign in zip(spec.start_poses, spec.end_poses, spec.tilt_signs)
        ]

    def poses_at(self, t: float) -> list[Pose]:
        """One pose per gripper at time t (s), clamped to [0, duration]."""
        return [p.pose(t) for p in self.paths]

    def sample_times(self, rate_hz: float) -> np.ndarray:
        """Times k / rate_hz (s) for k = 0, 1, ... up to the duration (T appended if it is
        not a multiple of 1 / rate_hz)."""
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise ValueError(f"rate must be > 0 Hz, got {rate_hz}")
        n = math.floor(self.duration * rate_hz + 1e-9)
        times = np.arange(n + 1) / rate_hz
        if times[-1] < self.duration - 1e-9:
            times = np.append(times, self.duration)
        return times

    def sample(self, rate_hz: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(times (K,) s, positions (K, G, 3) m, quaternions (K, G, 4) xyzw) at rate_hz."""
        times = self.sample_times(rate_hz)
        pos = np.stack([p.position(times) for p in self.paths], axis=1)
        quat = np.stack([p.quaternion(times) for p in self.paths], axis=1)
        return times, pos, quat
