"""Gripper motion limits: checked by trajectory_node before a fold is executed, and by the
backends on every step (a driver enforces its own limits). Pure: no rclpy.

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


def check_workspace_params(values: dict, changed: Sequence[str] = ()) -> str | None:
    """Cross check of the workspace_min / workspace_max parameters (m); the reason names the
    parameter being changed (workspace_max when only it changes, else workspace_min)."""
    lo, hi = list(values["workspace_min"]), list(values["workspace_max"])
    bad = [axis for axis, a, b in zip("xyz", lo, hi) if not a < b]
    if not bad:
        return None
    if "workspace_max" in changed and "workspace_min" not in changed:
        return f"workspace_max {hi} must be above workspace_min {lo} on every axis (not on {', '.join(bad)})"
    return f"workspace_min {lo} must be below workspace_max {hi} on every axis (not on {', '.join(bad)})"


def check_step(previous: dict, targets: dict, dt: float, lo: Sequence[float], hi: Sequence[float],
               max_speed: float) -> str | None:
    """A backend's own limits for one step of dt s: every target position (gripper -> Pose) inside
    the box [lo, hi] (m) and reached from the previous position (gripper -> Pose) no faster than
    max_speed (m/s). The reason, or None."""
    lo_a, hi_a = np.asarray(lo, float), np.asarray(hi, float)
    for g, pose in sorted(targets.items()):
        p = np.asarray(pose.position, float)
        if np.any(p < lo_a - 1e-9) or np.any(p > hi_a + 1e-9):
            return (f"gripper_{g} target {np.round(p, 4).tolist()} m is outside the backend's workspace "
                    f"[{', '.join(f'{v:g}' for v in lo_a)}] .. [{', '.join(f'{v:g}' for v in hi_a)}] m")
        prev = previous.get(g)
        if prev is not None and dt > 0:
            speed = float(np.linalg.norm(p - np.asarray(prev.position, float))) / dt
            if speed > max_speed * (1 + 1e-6) + 1e-9:
                return (f"gripper_{g} target needs {speed:.3f} m/s over one {dt:g} s step; the backend's "
                        f"limit is {max_speed:g} m/s")
    return None


# The search space of the lookup (trajectory.fan) and the ranges trajectory_node executes.
HEIGHT_RATIO_RANGE = (0.1, 1.0)  # -
TILT_RANGE_DEG = (0.0, 60.0)  # deg
DURATION_RANGE = (0.5, 60.0)  # s
SETTLE_RANGE = (0.0, 10.0)  # s
LAYER_OFFSET_RANGE = (1.0, 8.0)  # x thickness


def check_ranges(height_ratio: float, tilt_deg: float, duration: float, settle_time: float,
                 layer_offset_factor: float) -> str | None:
    """Reason one of a plan's numbers is outside what this pipeline executes (the lookup's
    search space for (h, tilt), the timing and layer ranges), or None."""
    for what, v, (lo, hi), unit in (("height_ratio", height_ratio, HEIGHT_RATIO_RANGE, ""),
                                    ("tilt_deg", tilt_deg, TILT_RANGE_DEG, " deg"),
                                    ("duration", duration, DURATION_RANGE, " s"),
                                    ("settle_time", settle_time, SETTLE_RANGE, " s"),
                                    ("layer_offset_factor", layer_offset_factor, LAYER_OFFSET_RANGE, "")):
        if not lo <= v <= hi:
            return f"{what} = {v:g}{unit} is outside [{lo:g}, {hi:g}]{unit}"
    return None


def check_plan_limits(plan) -> str | None:
    """Reason a (valid, core) FoldPlan is outside what this pipeline executes, or None: a known
    fold name, (h, tilt) inside the lookup's search space, duration, settle time and layer offset
    in their ranges, one or two grippers, tilt signs +-1."""
    from ..folding import FOLD_NAMES

    s = plan.spec
    if s.name not in FOLD_NAMES:
        return f"unknown fold {s.name!r}; known folds: {', '.join(FOLD_NAMES)}"
    reason = check_ranges(plan.height_ratio, plan.tilt_deg, plan.duration, plan.settle_time, s.layer_offset_factor)
    if reason:
        return reason
    if not 1 <= s.n_grippers <= 2:
        return f"a fold needs 1 or 2 grippers; got {s.n_grippers}"
    if any(abs(abs(x) - 1.0) > 1e-9 for x in s.tilt_signs):
        return f"tilt_signs must be +1 or -1, got {list(s.tilt_signs)}"
    return None
