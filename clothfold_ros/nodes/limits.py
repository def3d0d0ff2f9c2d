"""Gripper motion limits checked before a fold is executed. Pure: no rclpy.

Workspace: an axis-aligned box in the table frame (m). Speed: the peak Cartesian speed
of each gripper path (m/s), i.e. 1.875 L / T for minimum-jerk timing along arc length.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..trajectory import FoldTrajectory


def check_workspace(positions: np.ndarray, lo: Sequence[float], hi: Sequence[float]) -> str | None:
    """Reason the positions (K, G, 3) m leave the box [lo, hi], or None."""
    p = np.asarray(positions, dtype=float).reshape(-1, np.asarray(positions).shape[-2], 3)
    lo_a, hi_a = np.asarray(lo, float), np.asarray(hi, float)
    for g in range(p.shape[1]):
        out = np.any((p[:, g] < lo_a - 1e-12) | (p[:, g] > hi_a + 1e-12), axis=1)
        if out.any():
            k = int(np.argmax(out))
            return (f"gripper_{g} leaves the workspace [{', '.join(f'{v:g}' for v in lo_a)}] .. "
                    f"[{', '.join(f'{v:g}' for v in hi_a)}] m at sample {k}: {np.round(p[k, g], 4).tolist()} m")
    return None


def check_speed(trajectory: FoldTrajectory, max_speed: float) -> str | None:
    """Reason a gripper of the trajectory is faster than max_speed (m/s), or None."""
    for g, path in enumerate(trajectory.paths):
        if path.peak_speed > max_speed + 1e-12:
            return (f"gripper_{g} peak speed {path.peak_speed:.3f} m/s exceeds the limit {max_speed:g} m/s "
                    f"(path {path.length:.3f} m in {trajectory.duration:g} s; use a longer duration)")
    return None


def check_trajectory(trajectory: FoldTrajectory, rate_hz: float, lo: Sequence[float], hi: Sequence[float],
                     max_speed: float, n_grippers: int) -> str | None:
    """First reason the trajectory cannot be executed, or None."""
    if trajectory.spec.n_grippers > n_grippers:
        return f"fold {trajectory.spec.name!r} needs {trajectory.spec.n_grippers} grippers; {n_grippers} available"
    _, pos, _ = trajectory.sample(rate_hz)
    return check_workspace(pos, lo, hi) or check_speed(trajectory, max_speed)
