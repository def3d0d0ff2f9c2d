"""IPC cloth simulator (pure Python core, no ROS): see simulator.py, episode.py, runner.py."""
from .config import SimConfig
from .simulator import ClothSimulator, SimulationFailure, StepStats

__all__ = ["ClothSimulator", "SimConfig", "SimulationFailure", "StepStats", "FoldEpisode", "FoldOutcome", "run_fold"]


def __getattr__(name: str):  # lazy: episode/runner import the geometry core
    if name in ("FoldEpisode", "FoldOutcome"):
        from . import episode

        return getattr(episode, name)
    if name == "run_fold":
        from .runner import run_fold

        return run_fold
    raise AttributeError(name)
