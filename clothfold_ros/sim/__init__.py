"""IPC cloth simulator (pure Python core, no ROS): see simulator.py, episode.py, runner.py.

Only the settings are imported eagerly: `from clothfold_ros.sim.config import SimConfig`
(command-line defaults) does not load ipctk, numba or MKL.
"""
from .config import SimConfig

__all__ = ["ClothSimulator", "SimConfig", "SimulationFailure", "StepStats", "FoldEpisode", "FoldOutcome", "run_fold"]


def __getattr__(name: str):  # lazy, with plain imports (the architecture test reads them)
    if name in ("ClothSimulator", "SimulationFailure", "StepStats"):
        from . import simulator

        return getattr(simulator, name)
    if name in ("FoldEpisode", "FoldOutcome"):
        from . import episode

        return getattr(episode, name)
    if name == "run_fold":
        from .runner import run_fold

        return run_fold
    raise AttributeError(name)
