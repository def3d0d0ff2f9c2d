"""Headless fold runner: one (height ratio, tilt) trajectory on the IPC simulator, no ROS."""
from __future__ import annotations

from typing import Callable

import numpy as np

from ..folding import FoldSpec
from ..garment import Garment
from ..loss import fold_target
from ..materials import Material
from ..plan import FoldPlan
from .config import SimConfig
from .episode import FoldEpisode, FoldOutcome
from .simulator import ClothSimulator, SimulationFailure, StepStats


def flat_start(garment: Garment, material: Material) -> np.ndarray:
    """The garment's vertices lying flat at z = 2 t (docs/method.md section 1)."""
    x = np.array(garment.vertices, dtype=float)
    x[:, 2] = 2.0 * material.thickness
    return x


def run_fold(
    garment: Garment,
    spec: FoldSpec,
    material: Material,
    friction: float,
    height_ratio: float,
    tilt_deg: float,
    duration: float = 4.0,
    dt: float = 0.04,
    settle_time: float = 0.2,
    vertices: np.ndarray | None = None,
    target_base: np.ndarray | None = None,
    config: SimConfig | None = None,
    progress: Callable[[int, int, StepStats], None] | None = None,
) -> FoldOutcome:
    """`run_plan` for a plan given as its parts (dt is used when no config is given)."""
    return run_plan(garment, FoldPlan(spec, height_ratio, tilt_deg, duration, settle_time), material, friction,
                    vertices, target_base, config or SimConfig(dt=dt), progress)


def run_plan(
    garment: Garment,
    plan: FoldPlan,
    material: Material,
    friction: float,
    vertices: np.ndarray | None = None,
    target_base: np.ndarray | None = None,
    config: SimConfig | None = None,
    progress: Callable[[int, int, StepStats], None] | None = None,
) -> FoldOutcome:
    """Simulate one planned fold and return its outcome (never raises for a failed simulation).

    vertices: start state (default: flat at z = 2 t); target_base: the previous stage's
    target (default: the start state), so targets compose along a sequence.
    """
    cfg = config or SimConfig()
    start = flat_start(garment, material) if vertices is None else np.asarray(vertices, dtype=float)
    base = start if target_base is None else np.asarray(target_base, dtype=float)
    target = fold_target(base, plan.spec, material.thickness)
    sim = ClothSimulator(start, garment.triangles, material, friction, cfg, rest=flat_start(garment, material))
    episode = FoldEpisode(sim, plan.spec, target, plan.settle_time)
    n_motion = int(round(plan.duration / cfg.dt))
    if n_motion < 1:
        raise ValueError(f"the fold's motion ({plan.duration:g} s) is shorter than half a simulator step "
                         f"(dt {cfg.dt:g} s): it would be grasped and released without moving")
    n_total = n_motion + int(np.ceil(plan.settle_time / cfg.dt - 1e-9))
    try:
        episode.grasp()
        for k in range(1, n_motion + 1):
            stats = episode.advance(plan.trajectory.poses_at(k * cfg.dt))
            if progress:
                progress(k, n_total, stats)
        episode.release()
        episode.settle()
    except (SimulationFailure, ValueError) as err:
        if episode.failure is None:
            episode.failure = str(err)
    return episode.outcome()
