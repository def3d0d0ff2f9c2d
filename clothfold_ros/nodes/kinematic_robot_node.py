"""kinematic_robot_node: a cloth-less backend with the same contract as cloth_sim_node.

Grippers follow their commanded target poses exactly (lock-step, dt per step, paced at
most real_time_factor x wall time), /clock is published like the sim node's, the actual
poses go out on /gripper_<i>/pose and the finger opening on /gripper_<i>/state. When all
grippers have opened it publishes a /fold/result with success = true, loss = NaN and
reason "kinematic backend: no cloth" for the fold announced on /fold/active (a close with
none announced fails), so the pipeline runs unchanged against it. Keypoints
then come from keypoint_node with source = model (or a perception node).
"""
from __future__ import annotations

import math
import sys

from ..pose import Pose
from . import common
from .backend import LockStepBackend

NO_CLOTH = "kinematic backend: no cloth"


class KinematicRobotNode(LockStepBackend):
    def __init__(self) -> None:
        super().__init__("kinematic_robot_node", [])
        self.poses: dict[int, Pose] = {}
        self.steps = 0
        self.get_logger().info(f"kinematic robot: {self.n} gripper(s), dt {self.ls.dt_ns * 1e-9:g} s")

    def on_close(self, gripper: int, pose: Pose) -> None:
        if not self.ls.closed:
            if self.active is None:  # as cloth_sim_node: a result must name its fold
                raise ValueError("a gripper closed but no fold spec was announced on /fold/active")
            self.steps = 0
        self.poses[gripper] = pose

    def on_step(self, targets: dict[int, Pose]) -> None:
        self.poses.update(targets)
        self.steps += 1

    def on_open(self, gripper: int) -> None:
        pass

    def on_all_open(self) -> None:
        name = self.active.spec.name if self.active else "?"
        self.get_logger().info(f"fold {name}: grippers open after {self.steps} steps")
        self.publish_result(True, "", math.nan, self.steps)  # loss NaN: no cloth
        self.active = None


def main(argv: list[str] | None = None) -> int:
    full = list(sys.argv if argv is None else ["kinematic_robot_node", *argv])
    return common.run(KinematicRobotNode, full)


if __name__ == "__main__":
    sys.exit(main())
