"""One fold on a simulator: grasp, follow the gripper poses, release, settle, loss.

Shared by the headless runner and the ROS cloth-sim node so both give the same result
for the same inputs.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from ..arrays import finite_array
from ..folding import FoldSpec
from ..loss import mean_vertex_distance
from ..pose import Pose
from .simulator import ClothSimulator, SimulationFailure, StepStats


@dataclass
class FoldOutcome:
    """Result of one fold. `loss` is the mean vertex distance to the target (m)."""

    success: bool
    reason: str
    loss: float
    vertices: np.ndarray  # (N, 3) m, final cloth
    target: np.ndarray  # (N, 3) m
    steps: int
    newton_iterations: int
    wall_time: float  # s
    step_stats: list[StepStats] = field(default_factory=list)


class FoldEpisode:
    """Drives a ClothSimulator through one fold specification."""

    def __init__(self, sim: ClothSimulator, spec: FoldSpec, target: np.ndarray, settle_time: float = 0.2) -> None:
        target = finite_array(target, "fold target (m)", sim.x.shape)  # the cloth's shape, or a clear error
        if not 0 <= settle_time < float("inf"):
            raise ValueError(f"settle_time must be finite and >= 0 s, got {settle_time}")
        self.sim = sim
        self.spec = spec
        self.target = np.asarray(target, dtype=float)
        self.settle_time = settle_time
        self.stats: list[StepStats] = []
        self.failure: str | None = None
        self._wall = 0.0

    def _run(self, poses: dict[int, Pose] | None) -> StepStats | None:
        if self.failure is not None:
            raise SimulationFailure(self.failure)
        tic = time.perf_counter()
        try:
            stats = self.sim.step(poses)
        except SimulationFailure as err:
            self.failure = err.reason
            raise
        finally:
            self._wall += time.perf_counter() - tic
        self.stats.append(stats)
        return stats

    def grasp(self) -> None:
        """Close every gripper of the spec at its start pose."""
        for i, pose in enumerate(self.spec.start_poses):
            self.sim.grasp(i, pose)

    def advance(self, poses: Sequence[Pose]) -> StepStats:
        """One dt step with the grippers at `poses` (one per gripper) at the step's end."""
        if len(poses) != self.spec.n_grippers:
            raise ValueError(f"expected {self.spec.n_grippers} gripper poses, got {len(poses)}")
        return self._run({i: p for i, p in enumerate(poses) if i in self.sim.grasps})

    def release(self) -> None:
        for i in range(self.spec.n_grippers):
            self.sim.release(i)

    def settle(self) -> None:
        """Step `settle_time` with no gripper holding the cloth."""
        for _ in range(int(math.ceil(self.settle_time / self.sim.dt - 1e-9))):
            self._run(None)

    def outcome(self) -> FoldOutcome:
        ok = self.failure is None
        return FoldOutcome(
            success=ok,
            reason="" if ok else self.failure,
            loss=mean_vertex_distance(self.sim.x, self.target) if ok else float("nan"),
            vertices=self.sim.x.copy(),
            target=self.target,
            steps=len(self.stats),
            newton_iterations=sum(s.newton_iterations for s in self.stats),
            wall_time=self._wall,
            step_stats=list(self.stats),
        )
