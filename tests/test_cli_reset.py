"""`clothfold reset` against a running kinematic pipeline (a subprocess, as a user runs it): after a
fold, fold_planner_node forgets it (it plans the fold again). Nodes without the service
(cloth_sim_node, absent beside the kinematic robot; keypoint_node with source model, which tracks
no folds) are skipped by name when not asked for and an error when asked for."""
from __future__ import annotations

import subprocess
import sys

import pytest

from pipeline_helpers import FAST_KINEMATIC, running_pipeline

from clothfold_ros.nodes import conversions as rc

DOMAIN = 192


def clothfold(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-c", "import sys; from clothfold_ros.cli import main; sys.exit(main())", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)


def test_reset_clears_the_fold_history_of_keypoints_and_planner(monkeypatch):
    with running_pipeline(monkeypatch, DOMAIN, "kinematic", FAST_KINEMATIC, "test_reset") as (launcher, client):
        client.wait_keypoints(60)
        before = client.result_count()
        resp = client.plan("left_sleeve", execute=True)
        assert resp.success, resp.message
        res = client.wait_result("left_sleeve", 60, after=before)
        assert res.success, res.reason
        client.wait_keypoints(30, newer_than_ns=rc.time_to_ns(res.header.stamp) - 1)  # the clock stands at it
        again = client.plan("left_sleeve", execute=False)
        assert not again.success and "left_sleeve is done already" in again.message, again.message

        out = clothfold("reset", "--timeout", "3")
        assert out.returncode == 0, out.stdout + out.stderr
        assert "cloth_sim_node: skipped (no /cloth_sim_node/reset service within 3 s" in out.stderr
        assert "keypoint_node: skipped (no /keypoint_node/reset service" in out.stderr  # source model: no history
        assert "fold_planner_node: folds done and the flat body length forgotten" in out.stdout
        fresh = client.plan("left_sleeve", execute=False)
        assert fresh.success, fresh.message  # the planner forgot the fold

        named = clothfold("reset", "cloth_sim_node", "fold_planner_node", "--timeout", "2")
        assert named.returncode == 1
        assert "cloth_sim_node: FAILED: no /cloth_sim_node/reset service within 2 s" in named.stderr
        assert "fold_planner_node: folds done" in named.stdout


def test_reset_without_a_pipeline_fails_and_says_why(monkeypatch):
    monkeypatch.setenv("ROS_DOMAIN_ID", str(DOMAIN))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    out = clothfold("reset", "--timeout", "0.5")
    assert out.returncode == 1
    assert "no node answered (is the pipeline running on this ROS_DOMAIN_ID?)" in out.stderr
    for node in ("cloth_sim_node", "keypoint_node", "fold_planner_node"):
        assert f"{node}: skipped" in out.stderr


@pytest.mark.parametrize("bad", ["", "two words", "--timeout=0"])
def test_reset_rejects_bad_names_and_timeouts(bad):
    from clothfold_ros.nodes.reset import reset_nodes, service_name

    with pytest.raises(ValueError):
        if bad.startswith("--timeout"):
            reset_nodes(["keypoint_node"], timeout=0.0)
        else:
            service_name(bad)
    assert service_name("keypoint_node") == "/keypoint_node/reset"
    assert service_name("/robot/fold_planner_node/reset") == "/robot/fold_planner_node/reset"
