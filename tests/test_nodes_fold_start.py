"""A fold's start on a simulated clock that runs much faster than real time: trajectory_node puts
the start at least start_lead_wall wall seconds ahead (it measures the clock's pace), so the
backend gets /fold/active before its clock reaches the start even at a real-time factor of 50,
where start_delay (0.5 s of sim time) alone passes in 10 ms of wall time."""
from __future__ import annotations

from pipeline_helpers import FAST_KINEMATIC, running_pipeline

DOMAIN = 183


def test_fold_on_a_fifty_times_real_time_clock_starts_and_completes(monkeypatch):
    overrides = {**FAST_KINEMATIC, "kinematic_robot_node": {"real_time_factor": 50.0}}
    with running_pipeline(monkeypatch, DOMAIN, "kinematic", overrides, "test_fold_start") as (launcher, client):
        client.wait_keypoints(60)
        before = client.result_count()
        resp = client.plan("left_sleeve", execute=True)
        assert resp.success, resp.message
        res = client.wait_result("left_sleeve", 60, after=before)
        assert res.success and res.steps == 50, res.reason
