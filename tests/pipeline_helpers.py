"""Start the whole pipeline as separate processes on a test's own ROS domain (localhost only)."""
from __future__ import annotations

from contextlib import contextmanager
from typing import Iterator

from clothfold_ros.cli.launcher import Launcher


#: Parameter overrides of a quick kinematic pipeline: the planner's own (h, tilt), a 2 s fold
#: played 4x faster than real time, model keypoints twice a second.
FAST_KINEMATIC = {
    "fold_planner_node": {"selection": "parameter", "duration": 2.0},
    "kinematic_robot_node": {"real_time_factor": 4.0},
    "keypoint_node": {"model_period": 0.5},
}


@contextmanager
def running_pipeline(monkeypatch, domain: int, backend: str, overrides: dict[str, dict],
                     client_name: str, check_alive: bool = True) -> Iterator[tuple]:
    """(launcher, PipelineClient) for `backend` ("sim" or "kinematic") with parameter overrides.

    Every process is stopped on exit; a node that died during the test fails it (unless
    check_alive is false: the test kills one itself).
    """
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    from clothfold_ros.nodes.pipeline_client import PipelineClient

    with Launcher(domain_id=domain, echo=False) as launcher:
        launcher.start_pipeline(backend, overrides=overrides)
        try:
            with PipelineClient(client_name) as client:
                yield launcher, client
            if check_alive:
                launcher.check_alive()
        finally:
            dump_logs(launcher)  # captured: pytest shows it only when the test fails


def dump_logs(launcher, lines: int = 40) -> None:
    """Print the last lines of every process (shown by pytest when a test fails)."""
    for p in launcher.procs:
        print(f"---- {p.name} (exit {p.popen.poll()})")
        print("\n".join(p.lines[-lines:]))
