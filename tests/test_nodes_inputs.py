"""Nodes started alone, fed bad input (separate processes): a fold before any keypoints, a
corrupt cloth state, an unusable lookup table (refused unless the fallback is asked for), and
bad parameter files/values refused with a clear message."""
from __future__ import annotations

import math
import re
import time

import numpy as np
import pytest
from clothfold_msgs.msg import ClothState

from clothfold_ros.garment import make_shirt
from clothfold_ros.cli.launcher import Launcher, node_command
from clothfold_ros.nodes.conversions import cloth_state_to_msg, keypoints_from_msg

DOMAIN_TABLE = 152
DOMAIN_PARAMS = 153
DOMAIN_SET = 154


@pytest.fixture
def env(monkeypatch):
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    return monkeypatch


def test_planner_without_keypoints_bad_state_and_missing_table(env, tmp_path):
    env.setenv("ROS_DOMAIN_ID", str(DOMAIN_TABLE))
    from clothfold_ros.nodes.pipeline_client import PipelineClient

    missing = tmp_path / "no_tables"
    with Launcher(domain_id=DOMAIN_TABLE, echo=False) as launcher:
        kp_node = launcher.start("keypoint_node", node_command("keypoint_node", params={"source": "cloth_state",
                                                                                      "use_sim_time": False}))
        planner = launcher.start("fold_planner_node", node_command(
            "fold_planner_node", params={"selection": "table", "table_dir": str(missing)}))
        launcher.wait_for(planner, "ready", 60)
        launcher.wait_for(kp_node, "publishing keypoints", 60)
        with PipelineClient("test_nodes_inputs") as client:
            r = client.plan("left_sleeve", execute=False, wait_for_keypoints=False)
            assert not r.success and "no keypoints" in r.message
            # a corrupt cloth state: NaN vertex -> skipped, logged, the node keeps running
            g = make_shirt(1, max_area=5e-3)
            bad = cloth_state_to_msg(g.vertices, g.triangles, g.keypoint_ids, 3e-4, 1)
            pos = np.array(bad.positions)
            pos[5] = math.nan
            bad.positions = pos.astype(np.float32)
            client.state_pub.publish(bad)
            launcher.wait_for(kp_node, "bad cloth state skipped", 20)
            short = ClothState(positions=[0.0, 0.0], header=bad.header)
            client.state_pub.publish(short)
            launcher.wait_for(kp_node, "multiple of 3", 20)
            # a good state: keypoints follow it
            client.state_pub.publish(cloth_state_to_msg(g.vertices, g.triangles, g.keypoint_ids, 3e-4, 2))
            kp, ids = keypoints_from_msg(client.wait_keypoints(20))
            assert ids == g.keypoint_ids
            np.testing.assert_allclose(kp["armpit_left"], g.vertices[g.keypoint_ids["armpit_left"]], atol=1e-6)
            # the table is missing: refused with the reason (no silent fallback)
            deadline = time.monotonic() + 20
            while True:
                r = client.plan("left_sleeve", execute=False, wait_for_keypoints=False)
                if "no keypoints" not in r.message or time.monotonic() > deadline:
                    break
                time.sleep(0.2)
            assert not r.success and "table" in r.message and str(missing) in r.message
        launcher.check_alive()


def test_bad_parameters_are_refused_at_start(env):
    env.setenv("ROS_DOMAIN_ID", str(DOMAIN_PARAMS))
    # the refusal each node prints (a regex): its one "fatal" line names the parameter, the value and
    # the rule; a crash of another kind that merely mentions the parameter's name does not pass
    cases = {
        "trajectory_node": ({"workspace_min": [1.0, 0.0, 0.0], "workspace_max": [0.5, 1.0, 1.0]},
                            re.escape("bad parameters: workspace_min [1.0, 0.0, 0.0] must be below workspace_max "
                                      "[0.5, 1.0, 1.0] on every axis (not on x)")),
        "cloth_sim_node": ({"max_area": 1.0}, r"Parameter max_area out of range .*value: 1\.0\b"),
        "fold_planner_node": ({"selection": "magic"}, r"selection must be one of .*; got 'magic'"),
        "kinematic_robot_node": ({"dt": -0.04}, r"Parameter dt out of range .*value: -0\.04\b"),
        "keypoint_node": ({"source": "camera"}, r"source must be one of .*; got 'camera'"),
    }
    with Launcher(domain_id=DOMAIN_PARAMS, echo=False) as launcher:
        procs = {n: launcher.start(n, node_command(n, params=p)) for n, (p, _) in cases.items()}
        for name, proc in procs.items():
            assert proc.popen.wait(60) == 2, name
            launcher.wait_for(proc, r"\] fatal: \w+: .*" + cases[name][1], 5)


def test_parameter_changes_are_checked(env):
    env.setenv("ROS_DOMAIN_ID", str(DOMAIN_SET))
    import rclpy
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from clothfold_ros.nodes import params, trajectory_node

    ctx = rclpy.Context()
    rclpy.init(args=[], context=ctx)
    try:
        node = Node("param_check", context=ctx)
        params.declare(node, trajectory_node.PARAMS, trajectory_node._param_check)
        ok = node.set_parameters([Parameter("rate", value=50.0)])[0]
        assert ok.successful and params.value(node, "rate") == 50.0
        for change, words in [(Parameter("rate", value=0.0), "out of range"),
                              (Parameter("max_speed", value=math.inf), "max_speed"),
                              (Parameter("workspace_min", value=[0.0, 0.0, 2.0]), "below workspace_max"),
                              (Parameter("workspace_max", value=[1.0, 1.0]), "3 elements"),
                              # the refusal names the parameter that was set
                              (Parameter("workspace_max", value=[1.0, 1.0, -0.5]), "workspace_max [1.0, 1.0, -0.5]"),
                              (Parameter("workspace_min", value=[-1.0, 2.0, 0.0]), "workspace_min [-1.0, 2.0, 0.0]")]:
            res = node.set_parameters([change])[0]
            assert not res.successful and words in res.reason, (change.name, res.reason)
        assert params.value(node, "rate") == 50.0
        # one lookahead's burst of target poses must fit half the target topic's history (500)
        assert node.set_parameters([Parameter("lookahead", value=5.0)])[0].successful  # 250 at 50 Hz
        res = node.set_parameters([Parameter("rate", value=150.0)])[0]
        assert not res.successful and "rate x lookahead = 750 target poses" in res.reason, res.reason
        ro = node.set_parameters([Parameter("n_grippers", value=1)])[0]
        assert not ro.successful  # read-only
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)


def test_whole_numbers_for_double_parameters_are_taken(env):
    """`-p lookahead:=0` (what docs/robot-interface.md advises for a driver) and an all-integer
    `table_from_camera` reach rclpy as INTEGER / INTEGER_ARRAY: declared as doubles they stopped
    the node (InvalidParameterTypeException). They are taken as the doubles they name; a later
    `ros2 param set` with an integer is refused with rclpy's reason, the node keeps its value."""
    env.setenv("ROS_DOMAIN_ID", str(DOMAIN_SET))
    import rclpy
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from clothfold_ros.nodes import keypoint_node, params, trajectory_node

    ctx = rclpy.Context()
    rclpy.init(args=[], context=ctx)
    try:
        args = ["--ros-args", "-p", "lookahead:=0", "-p", "rate:=50", "-p", "workspace_min:=[-2, -2, 0]"]
        node = Node("whole_numbers", context=ctx, cli_args=args)
        params.declare(node, trajectory_node.PARAMS, trajectory_node._param_check)
        assert (params.value(node, "lookahead"), params.value(node, "rate")) == (0.0, 50.0)
        assert params.value(node, "workspace_min") == [-2.0, -2.0, 0.0]
        assert all(isinstance(v, float) for v in params.value(node, "workspace_min"))
        res = node.set_parameters([Parameter("lookahead", Parameter.Type.INTEGER, 1)])[0]
        assert not res.successful and "DOUBLE" in res.reason and params.value(node, "lookahead") == 0.0
        node.destroy_node()
        cam = Node("whole_numbers_cam", context=ctx, cli_args=["--ros-args", "-p", "table_from_camera:=[0,0,1,1,0,0,0]"])
        params.declare(cam, keypoint_node.PARAMS)
        assert params.value(cam, "table_from_camera") == [0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0]
        cam.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
