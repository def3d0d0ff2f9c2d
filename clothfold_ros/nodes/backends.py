"""The robot backends and the node executables: the one list each is read from.

Read by cli/launcher.py (`clothfold launch`, `clothfold demo`), cli/run.py, the launch file
and setup.py (entry points); standard library only, so setup.py and the launch file can
load it without the package's dependencies. Adding a backend: one `Backend` entry here
and its node module `clothfold_ros/nodes/<node>.py` (a `backend.LockStepBackend` subclass
with `main()`, docs/robot-interface.md); its parameters may go into config/clothfold.yaml.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Backend:
    """A robot backend: the node started for it (None: none, a real driver runs instead),
    whether it publishes /clock (the pipeline nodes then default to use_sim_time), the
    keypoint_node `source` it needs (None: the parameters file's), whether
    `clothfold demo` can fold with it, and a one-line description."""

    name: str
    node: str | None
    clock: bool
    keypoint_source: str | None
    demo: bool
    help: str


BACKENDS: dict[str, Backend] = {b.name: b for b in (
    Backend("sim", "cloth_sim_node", clock=True, keypoint_source=None, demo=True,
            help="the IPC cloth simulator, lock-stepped to the pipeline"),
    Backend("kinematic", "kinematic_robot_node", clock=True, keypoint_source="model", demo=True,
            help="grippers only, no cloth (keypoints of the flat model shirt)"),
    Backend("none", None, clock=False, keypoint_source=None, demo=False,
            help="no backend: a real driver runs instead (no /clock)"),
)}
DEFAULT_BACKEND = "sim"
PIPELINE: tuple[str, ...] = ("keypoint_node", "fold_planner_node", "trajectory_node")
TOOLS: tuple[str, ...] = ("recorder_node", "player_node")
#: Every node executable (module clothfold_ros/nodes/<name>.py with main()).
NODES: tuple[str, ...] = PIPELINE + tuple(b.node for b in BACKENDS.values() if b.node) + TOOLS


def backend(name: str) -> Backend:
    """The backend `name` (ValueError naming the known ones otherwise)."""
    try:
        return BACKENDS[name]
    except KeyError:
        raise ValueError(f"unknown backend {name!r}; choose from {', '.join(BACKENDS)}") from None
