"""A fold's start on a simulated clock that runs much faster than real time: trajectory_node puts
the start at least start_lead_wall wall seconds ahead (it measures the clock's pace), so the
backend gets /fold/active before its clock reaches the start even at a real-time factor of 50,
where start_delay (0.5 s of sim time) alone passes in 10 ms of wall time."""
from __future__ import annotations

import pytest

from pipeline_helpers import FAST_KINEMATIC, running_pipeline

DOMAIN = 183
DOMAIN_ALONE = 190


def test_fold_on_a_fifty_times_real_time_clock_starts_and_completes(monkeypatch):
    overrides = {**FAST_KINEMATIC, "kinematic_robot_node": {"real_time_factor": 50.0}}
    with running_pipeline(monkeypatch, DOMAIN, "kinematic", overrides, "test_fold_start") as (launcher, client):
        client.wait_keypoints(60)
        before = client.result_count()
        resp = client.plan("left_sleeve", execute=True)
        assert resp.success, resp.message
        res = client.wait_result("left_sleeve", 60, after=before)
        assert res.success and res.steps == 50, res.reason


def test_the_start_lead_uses_the_clock_s_fastest_pace():
    """A backend clock starved for 2 s, then at 50x for 0.6 s: the mean pace over the 3 s
    window (about 10x) would put the start 5 s of clock time ahead, 0.1 s of wall time at 50x;
    the fastest pace over 0.5 s stretches is the 50x the clock runs at now."""
    from clothfold_ros.nodes.trajectory_node import fastest_pace

    s = 1e9
    stalled = [(0.1 * k, int(0.1 * s * k)) for k in range(5)]  # 1x for 0.4 s
    stalled += [(0.4 + 0.1 * k, int(0.4 * s)) for k in range(1, 21)]  # stopped until 2.4 s
    burst = [(2.4 + 0.1 * k, int(0.4 * s + 5 * s * k)) for k in range(1, 7)]  # 50x until 3.0 s
    samples = stalled + burst
    (w0, c0), (w1, c1) = samples[0], samples[-1]
    assert (c1 - c0) / (w1 - w0) < 11 * s  # the mean
    assert fastest_pace(samples) == pytest.approx(50 * s)
    assert fastest_pace(stalled[:3]) == pytest.approx(1 * s)  # shorter than a span: over all of them
    assert fastest_pace(stalled[:1]) == 0.0
    assert fastest_pace([(0.0, 0), (0.3, 0), (0.6, 0)]) == 0.0


def test_clock_samples_skip_a_clock_at_zero_and_restart_when_it_goes_back():
    """Samples taken before the first /clock (0) would make its jump to T look like a pace of
    T per sample interval; a clock that goes back (a replay loops) starts a new window."""
    from collections import deque
    from types import SimpleNamespace

    from clothfold_ros.nodes.trajectory_node import TrajectoryNode

    readings = iter([0, 0, 100 * 10**9, 100 * 10**9 + 10**8, 5 * 10**9])
    node = SimpleNamespace(_clock_samples=deque(), now_ns=lambda: next(readings))
    for _ in range(4):
        TrajectoryNode._sample_clock(node)
    assert [c for _, c in node._clock_samples] == [100 * 10**9, 100 * 10**9 + 10**8]
    TrajectoryNode._sample_clock(node)
    assert [c for _, c in node._clock_samples] == [5 * 10**9]


def test_a_fold_is_not_started_before_the_backend_can_deliver_its_result(monkeypatch):
    """/fold/result is volatile: the client waits for a matched result publisher before asking
    for a fold, and says so when none comes (here: no backend on the domain at all)."""
    monkeypatch.setenv("ROS_DOMAIN_ID", str(DOMAIN_ALONE))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    from clothfold_ros.nodes.pipeline_client import PipelineClient

    with PipelineClient("test_fold_start_alone") as client:
        with pytest.raises(TimeoutError, match="/fold/result publisher"):
            client.plan("left_sleeve", execute=True, timeout=1.0)
        with pytest.raises(TimeoutError, match="/plan_fold not available"):
            client.plan("left_sleeve", execute=False, timeout=1.0)
