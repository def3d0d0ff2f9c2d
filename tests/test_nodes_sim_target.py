"""cloth_sim_node composes a fold's loss target onto the folds its planner assumed made
(FoldSpec.folds_done), as the node started them: after a failed fold the target follows the
planner's (and keypoint_node's) history, not only the folds whose simulation completed."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from clothfold_ros.folding import fold_spec
from clothfold_ros.garment import make_shirt
from clothfold_ros.loss import fold_target

T = 3e-4  # m, cloth thickness


class _Log:
    def __init__(self) -> None:
        self.lines: list[str] = []

    def info(self, msg: str) -> None:
        self.lines.append(msg)

    warn = info


def test_the_target_follows_the_folds_the_planner_assumed():
    from clothfold_ros.nodes.cloth_sim_node import ClothSimNode

    g = make_shirt(1, max_area=5e-3)
    left, right = (fold_spec(n, g.keypoints()) for n in ("left_sleeve", "right_sleeve"))
    after_left = fold_target(g.vertices, left, T)
    after_both = fold_target(after_left, right, T)
    log = _Log()
    # left_sleeve completed; right_sleeve started and its simulation failed (not composed)
    node = SimpleNamespace(flat=g.vertices.copy(), target_base=after_left, material=SimpleNamespace(thickness=T),
                           fold_specs={"left_sleeve": left, "right_sleeve": right}, get_logger=lambda: log)
    side = fold_spec("left_side", g.keypoints())
    plan = lambda done: SimpleNamespace(spec=side, folds_done=done)  # noqa: E731
    assert ClothSimNode.base_for(node, plan(None)) is after_left  # not given: the folds completed here
    np.testing.assert_array_equal(ClothSimNode.base_for(node, plan(("left_sleeve",))), after_left)
    assert not log.lines
    # the cloud showed the failed right sleeve fold made: the planner (keypoint_node's history) says so
    np.testing.assert_array_equal(ClothSimNode.base_for(node, plan(("left_sleeve", "right_sleeve"))), after_both)
    assert "composed onto the planner's folds" in log.lines[-1]
    np.testing.assert_array_equal(ClothSimNode.base_for(node, plan(())), g.vertices)  # laid flat again
    # a fold this node never started: the folds completed here, with a warning
    assert ClothSimNode.base_for(node, plan(("left_sleeve", "right_sleeve", "right_side"))) is after_left
    assert "never simulated ['right_side']" in log.lines[-1]
