"""fold_planner_node plans only from keypoints of the cloth as it lies now: keypoints stamped
before the newest /fold/result (of any outcome: the cloth may have moved) are refused with a
reason that PipelineClient.plan retries on, until newer keypoints arrive. It places the middle
line with the body length it measured on the flat shirt. In-process node, isolated ROS
domain; the callbacks are called directly."""
from __future__ import annotations

import time

import numpy as np
import pytest
import rclpy
from clothfold_msgs.msg import FoldResult

from clothfold_ros.folding import FOLD_SEQUENCE, fold_spec
from clothfold_ros.garment import make_shirt
from clothfold_ros.loss import fold_target
from clothfold_ros.nodes import conversions as rc
from clothfold_ros.perception.visible import visible_keypoints

S = 1_000_000_000


def test_keypoints_older_than_the_last_fold_result_are_not_planned_from(monkeypatch):
    from clothfold_ros.nodes.fold_planner_node import FoldPlannerNode

    g = make_shirt(1, max_area=5e-3)
    kp = lambda t: rc.keypoints_to_msg(g.keypoints(), t)  # noqa: E731
    ctx = rclpy.Context()
    rclpy.init(args=["--ros-args", "-p", "selection:=parameter", "-p", "use_sim_time:=true",
                     "-p", "fresh_keypoints_wait:=2.0"], context=ctx,
               domain_id=184)
    init = rclpy.node.Node.__init__
    monkeypatch.setattr(rclpy.node.Node, "__init__", lambda self, *a, **k: init(self, *a, **{"context": ctx, **k}))
    try:
        node = FoldPlannerNode()
        node.on_keypoints(kp(10 * S))
        assert node.plan("left_sleeve").fold_name == "left_sleeve"
        node.on_result(FoldResult(header=rc.header(14 * S), fold_name="left_sleeve", success=False, reason="x"))
        with pytest.raises(ValueError, match=r"^no keypoints of the cloth as it lies now.*10\.000 s.*14\.000 s"):
            node.plan("left_sleeve")
        node.on_keypoints(kp(14 * S))  # the cloth's state at the result: planned from
        assert node.plan("left_sleeve").fold_name == "left_sleeve"
        node.on_result(FoldResult(header=rc.header(20 * S), fold_name="left_sleeve", success=True, loss=0.004))
        with pytest.raises(ValueError, match="no keypoints of the cloth as it lies now"):
            node.plan("right_sleeve")
        node.on_keypoints(kp(21 * S))
        assert node.plan("right_sleeve").fold_name == "right_sleeve"
        # a result that brings no newer keypoints (a fold cancelled before it moved the cloth, a
        # rejected fit) blocks planning only fresh_keypoints_wait (2 s here), then it goes on
        node.on_result(FoldResult(header=rc.header(30 * S), fold_name="right_sleeve", success=False, reason="x"))
        with pytest.raises(ValueError, match="no keypoints of the cloth as it lies now"):
            node.plan("right_sleeve")
        time.sleep(2.1)
        assert node.plan("right_sleeve").fold_name == "right_sleeve"
        node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)


def test_the_middle_line_comes_from_the_body_length_seen_flat(monkeypatch):
    """After four folds the visible shoulders are the sleeve creases' corners; the planner
    still puts the middle line where the study did, from the length it measured flat. Reset
    (it never saw the shirt flat): the line from the visible shoulders, above the study's."""
    from clothfold_ros.nodes.fold_planner_node import FoldPlannerNode

    g = make_shirt(1, max_area=5e-4)
    v, specs = g.vertices.copy(), []
    for name in FOLD_SEQUENCE[:4]:  # the ideal folds, planned as the planner does
        specs.append(fold_spec(name, visible_keypoints(g, v, specs), folds_done=[s.name for s in specs]))
        v = fold_target(v, specs[-1], 3e-4)  # 0.3 mm cloth
    folded = visible_keypoints(g, v, specs)
    study = fold_spec("middle", g.keypoints())
    ctx = rclpy.Context()
    rclpy.init(args=["--ros-args", "-p", "selection:=parameter"], context=ctx, domain_id=185)
    init = rclpy.node.Node.__init__
    monkeypatch.setattr(rclpy.node.Node, "__init__", lambda self, *a, **k: init(self, *a, **{"context": ctx, **k}))

    def middle_line_offset(node) -> float:
        msg = node.plan("middle")
        p = np.array([msg.line_point.x, msg.line_point.y, msg.line_point.z])
        return float(study.side_of_line(p))

    try:
        node = FoldPlannerNode()
        node.on_keypoints(rc.keypoints_to_msg(g.keypoints(), 1 * S))
        node.plan("left_sleeve")  # measured flat here
        for k, name in enumerate(FOLD_SEQUENCE[:4]):
            node.on_result(FoldResult(header=rc.header((2 + k) * S), fold_name=name, success=True, loss=0.004))
        node.on_keypoints(rc.keypoints_to_msg(folded, 10 * S))
        assert middle_line_offset(node) == pytest.approx(0.0, abs=1e-6)
        node.on_reset(None, type("Resp", (), {})())
        for k, name in enumerate(FOLD_SEQUENCE[:4]):
            node.on_result(FoldResult(header=rc.header((12 + k) * S), fold_name=name, success=True, loss=0.004))
        node.on_keypoints(rc.keypoints_to_msg(folded, 20 * S))
        assert 0.01 < abs(middle_line_offset(node)) < 0.04  # 25 mm on shape 1
        node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)


def test_the_folds_the_keypoints_follow_are_the_history_planned_with(monkeypatch):
    """One history: keypoints that name the folds they follow (keypoint_node's, which may adopt a
    failed fold the cloud shows) override the planner's count of successful results; a fold
    they follow is not planned again; a message naming an unknown fold is ignored."""
    from clothfold_ros.nodes.fold_planner_node import FoldPlannerNode

    g = make_shirt(1, max_area=5e-4)
    v, specs = g.vertices.copy(), []
    for name in FOLD_SEQUENCE[:4]:
        specs.append(fold_spec(name, visible_keypoints(g, v, specs), folds_done=[s.name for s in specs]))
        v = fold_target(v, specs[-1], 3e-4)
    ctx = rclpy.Context()
    rclpy.init(args=["--ros-args", "-p", "selection:=parameter"], context=ctx, domain_id=187)
    init = rclpy.node.Node.__init__
    monkeypatch.setattr(rclpy.node.Node, "__init__", lambda self, *a, **k: init(self, *a, **{"context": ctx, **k}))
    study = fold_spec("middle", g.keypoints())
    try:
        node = FoldPlannerNode()
        node.on_keypoints(rc.keypoints_to_msg(g.keypoints(), 1 * S, folds=[]))
        node.plan("left_sleeve")
        # every fold failed by its results, but the keypoints show the four folds made
        for k, name in enumerate(FOLD_SEQUENCE[:4]):
            node.on_result(FoldResult(header=rc.header((2 + k) * S), fold_name=name, success=False, reason="x"))
        node.on_keypoints(rc.keypoints_to_msg(visible_keypoints(g, v, specs), 10 * S, folds=FOLD_SEQUENCE[:4]))
        msg = node.plan("middle")  # planned on the hem the cloth shows: the study's middle fold
        assert msg.folds_known and list(msg.folds_done) == list(FOLD_SEQUENCE[:4])  # what cloth_sim_node composes
        assert study.side_of_line(np.array([msg.line_point.x, msg.line_point.y, 0.0])) == pytest.approx(0, abs=1e-6)
        for a, b in zip(study.start_poses, msg.start_poses):
            assert np.hypot(a.position[0] - b.position.x, a.position[1] - b.position.y) < 1e-6
        with pytest.raises(ValueError, match=r"folds made are \[left_sleeve, .*left_side is done already"):
            node.plan("left_side")
        bad = rc.keypoints_to_msg(g.keypoints(), 11 * S, folds=["left_sleeve", "no_such_fold"])
        node.on_keypoints(bad)  # ignored: the last good keypoints stay
        assert node.keypoints_stamp == 10 * S and node.keypoint_folds == list(FOLD_SEQUENCE[:4])
        node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)


def test_keypoints_older_than_the_last_result_do_not_bring_their_folds(monkeypatch):
    """Planned from keypoints that predate the last result (fresh_keypoints_wait over), the
    history is the fold results', not the keypoints' older list: no fold planned twice, and
    the plan tells the sim the sleeve is made."""
    from clothfold_ros.nodes.fold_planner_node import FoldPlannerNode

    g = make_shirt(1, max_area=5e-3)
    ctx = rclpy.Context()
    rclpy.init(args=["--ros-args", "-p", "selection:=parameter", "-p", "fresh_keypoints_wait:=0.0"], context=ctx,
               domain_id=188)
    init = rclpy.node.Node.__init__
    monkeypatch.setattr(rclpy.node.Node, "__init__", lambda self, *a, **k: init(self, *a, **{"context": ctx, **k}))
    try:
        node = FoldPlannerNode()
        node.on_keypoints(rc.keypoints_to_msg(g.keypoints(), 1 * S, folds=[]))
        node.on_result(FoldResult(header=rc.header(2 * S), fold_name="left_sleeve", success=True, loss=0.004))
        with pytest.raises(ValueError, match=r"folds made are \[left_sleeve\]: left_sleeve is done already"):
            node.plan("left_sleeve")
        msg = node.plan("right_sleeve")
        assert msg.folds_known and list(msg.folds_done) == ["left_sleeve"]
        node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)


def test_setting_table_dir_reloads_the_tables(monkeypatch, tmp_path):
    """`table_dir` set at run time takes effect: a selector that failed to load (no tables there)
    is loaded again from the new directories (it was cached for the node's life, the set
    reported as successful without effect)."""
    import sys
    from pathlib import Path

    from rclpy.parameter import Parameter

    from clothfold_ros.nodes.fold_planner_node import FoldPlannerNode

    sys.path.insert(0, str(Path(__file__).parent))
    from test_lookup_select import _bowl, _table, _write_table_dir

    pts = np.arange(0, 134, 3)
    _write_table_dir(tmp_path / "tables" / "shape1", _table("shape1", _bowl(66)[pts], points=pts))
    ctx = rclpy.Context()
    rclpy.init(args=["--ros-args", "-p", "selection:=table", "-p", f"table_dir:={tmp_path / 'none'}"], context=ctx,
               domain_id=189)
    init = rclpy.node.Node.__init__
    monkeypatch.setattr(rclpy.node.Node, "__init__", lambda self, *a, **k: init(self, *a, **{"context": ctx, **k}))
    try:
        node = FoldPlannerNode()
        with pytest.raises(RuntimeError, match="selector unavailable.*none"):
            node.selector()
        assert node.set_parameters([Parameter("table_dir", value=str(tmp_path / "tables"))])[0].successful
        assert sorted(node.selector().tables) == ["shape1"]
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)


def test_an_unusable_table_falls_back_to_the_parameters_only_when_asked(monkeypatch, tmp_path):
    """selection table with no tables: refused with the reason, unless fallback_to_parameters,
    which plans with height_ratio / tilt_deg."""
    from rclpy.parameter import Parameter

    from clothfold_ros.nodes.fold_planner_node import FoldPlannerNode

    g = make_shirt(1, max_area=5e-3)
    ctx = rclpy.Context()
    rclpy.init(args=["--ros-args", "-p", "selection:=table", "-p", f"table_dir:={tmp_path / 'none'}",
                     "-p", "height_ratio:=0.377", "-p", "tilt_deg:=12.0"], context=ctx, domain_id=196)
    init = rclpy.node.Node.__init__
    monkeypatch.setattr(rclpy.node.Node, "__init__", lambda self, *a, **k: init(self, *a, **{"context": ctx, **k}))
    try:
        node = FoldPlannerNode()
        node.on_keypoints(rc.keypoints_to_msg(g.keypoints(), 1 * S))
        with pytest.raises(RuntimeError, match="table selection failed: lookup table selector unavailable .*none"):
            node.plan("left_sleeve")
        assert node.set_parameters([Parameter("fallback_to_parameters", value=True)])[0].successful
        spec = node.plan("left_sleeve")
        assert (spec.height_ratio, spec.tilt_deg) == (0.377, 12.0)
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
