"""keypoint_node: the shirt's semantic keypoints on /keypoints (clothfold_msgs/Keypoints, latched).

source = "cloth_state": subscribes /cloth/state and publishes the positions of the
keypoint vertices of the current mesh (so the keypoints track the cloth as it folds),
stamped like the state, frame "table". source = "model": publishes the flat shirt's
keypoints (parameters shape, max_area) once a second, for backends without a cloth
(kinematic_robot_node); a real robot replaces this node by a perception node publishing
/keypoints. A bad cloth state (NaN, wrong sizes) is logged and skipped; the last good
keypoints stay published.
"""
from __future__ import annotations

import sys

import numpy as np
from clothfold_msgs.msg import ClothState, Keypoints
from rclpy.node import Node

from .. import ros_conversions as rc
from . import common, params
from .params import Param

PARAMS = [
    Param("source", "cloth_state", "where keypoints come from: the cloth state topic or the flat shirt model",
          choices=("cloth_state", "model"), read_only=True),
    params.SHAPE,
    Param("max_area", 1e-3, "mesh max triangle area (m^2) of the model shirt (source = model)",
          range=(1e-5, 1e-2), read_only=True),
    Param("model_period", 1.0, "republish period of the model keypoints (s)", range=(0.05, 60.0)),
]


class KeypointNode(Node):
    def __init__(self) -> None:
        super().__init__("keypoint_node")
        params.declare(self, PARAMS)
        self.pub = self.create_publisher(Keypoints, common.KEYPOINTS, common.LATCHED)
        self.count = 0
        self.errors = 0
        source = params.value(self, "source")
        if source == "cloth_state":
            self.create_subscription(ClothState, common.CLOTH_STATE, self.on_state, common.LATCHED)
            self.get_logger().info(f"publishing keypoints of the cloth on {common.CLOTH_STATE}")
        else:
            from ..garment import make_shirt

            g = make_shirt(params.value(self, "shape"), max_area=params.value(self, "max_area"))
            self.model = (g.keypoints(), dict(g.keypoint_ids))
            self.publish_model()
            self.create_timer(params.value(self, "model_period"), self.publish_model)
            self.get_logger().info(f"publishing the flat model shirt's keypoints (shape {params.value(self, 'shape')})")

    def publish_model(self) -> None:
        kp, ids = self.model
        self.pub.publish(rc.keypoints_to_msg(kp, self.get_clock().now().nanoseconds, ids))

    def on_state(self, msg: ClothState) -> None:
        try:
            state = rc.cloth_state_from_msg(msg)
            if not state.keypoint_ids:
                raise ValueError("cloth state names no keypoint vertices")
            kp = state.keypoints()
            if not all(np.all(np.isfinite(p)) for p in kp.values()):
                raise ValueError("keypoints are not finite")
        except ValueError as err:
            self.errors += 1
            self.get_logger().error(f"bad cloth state skipped ({self.errors} so far): {err}")
            return
        self.pub.publish(rc.keypoints_to_msg(kp, state.stamp_ns, state.keypoint_ids))
        self.count += 1


def main(argv: list[str] | None = None) -> int:
    full = list(sys.argv if argv is None else ["keypoint_node", *argv])
    return common.run(KeypointNode, full)


if __name__ == "__main__":
    sys.exit(main())
