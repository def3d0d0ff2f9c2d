"""FoldPlan: one fold as it is executed, the one type from the planner to the simulator or robot.

A plan is the fold (its `FoldSpec`: fold line, gripper start and end poses), the gripper
path's two numbers (height ratio, tilt in degrees), its timing (motion duration and settle
time after release, s) and its stage in the sequence. It is checked once, when built: the
spec checks its geometry, and the plan builds its `FoldTrajectory` (which checks the path
parameters) and checks timing and stage. Execution limits of a particular robot (search
space, workspace, speed) are policy, checked by the trajectory node (`nodes/limits.py`).
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field

from .folding import FoldSpec
from .trajectory import FoldTrajectory


@dataclass(frozen=True, eq=False)
class FoldPlan:
    """A fold with its path parameters and timing (SI units: s; tilt in degrees)."""

    spec: FoldSpec
    height_ratio: float
    tilt_deg: float
    duration: float = 4.0  # s, gripper motion
    settle_time: float = 0.2  # s, after release
    stage: int = 0  # index in the fold sequence
    trajectory: FoldTrajectory = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.spec, FoldSpec):
            raise ValueError(f"a fold plan needs a FoldSpec, got {type(self.spec).__name__}")
        if not (math.isfinite(self.settle_time) and self.settle_time >= 0):
            raise ValueError(f"settle_time must be >= 0 s, got {self.settle_time}")
        if not (isinstance(self.stage, numbers.Real) and math.isfinite(self.stage)) or int(self.stage) != self.stage \
                or self.stage < 0:
            raise ValueError(f"stage must be an integer >= 0, got {self.stage}")
        object.__setattr__(self, "trajectory",  # checks height ratio, tilt and duration
                           FoldTrajectory(self.spec, self.height_ratio, self.tilt_deg, self.duration))
