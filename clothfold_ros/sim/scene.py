"""One simulated scene from one set of settings: garment, material, flat start, solver settings.

The headless command (`clothfold simulate`), the table sweep and cloth_sim_node build their
simulator through `build_scene`, so the three share defaults (SimConfig's, the garment's
mesh resolution, materials.DEFAULT_FRICTION) and one validity check (`SceneSettings`).
SI units: m^2, s, m/s.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..garment import DEFAULT_MAX_AREA, SHAPES, Garment, make_shirt
from ..materials import DEFAULT_FRICTION, Material, material
from .config import SimConfig
from .runner import flat_start


@dataclass(frozen=True)
class SceneSettings:
    """What determines a scene: shirt shape preset (garment.SHAPES), mesh max triangle area
    (m^2), material preset name, Coulomb friction coefficient of every contact, time step
    dt (s), Newton tolerance (RMS(|dx|)/dt, m/s) and iteration cap. Checked on creation
    (ValueError naming the setting)."""

    shape: int = 1
    max_area: float = DEFAULT_MAX_AREA
    material: str = "cotton"
    friction: float = DEFAULT_FRICTION
    dt: float = SimConfig.dt
    newton_tol: float = SimConfig.newton_tol
    max_newton_iterations: int = SimConfig.max_newton_iterations
    threads: int = 1  # PARDISO and CCD threads (results are bit-for-bit the same for any count)

    def __post_init__(self) -> None:
        if self.shape not in SHAPES:
            raise ValueError(f"unknown shirt shape {self.shape!r}; known: {', '.join(map(str, SHAPES))}")
        material(self.material)
        if not (math.isfinite(self.max_area) and self.max_area > 0):
            raise ValueError(f"max_area must be > 0 m^2, got {self.max_area}")
        if not (math.isfinite(self.friction) and self.friction >= 0):
            raise ValueError(f"friction must be a finite coefficient >= 0, got {self.friction}")
        for k in ("dt", "newton_tol"):
            if not (math.isfinite(getattr(self, k)) and getattr(self, k) > 0):
                raise ValueError(f"{k} must be > 0, got {getattr(self, k)}")
        self.config()  # SimConfig's own checks (iteration cap)

    def config(self) -> SimConfig:
        """The solver settings (SimConfig defaults for everything not set here)."""
        return SimConfig(dt=self.dt, newton_tol=self.newton_tol, max_newton_iterations=self.max_newton_iterations,
                         solver_threads=self.threads, ccd_threads=self.threads)


@dataclass(frozen=True, eq=False)
class Scene:
    """A built scene: the meshed garment, its material, the flat start state (N, 3) m
    (z = 2 t, docs/method.md section 1) and the solver settings."""

    settings: SceneSettings
    garment: Garment
    material: Material
    flat: np.ndarray
    config: SimConfig

    @property
    def friction(self) -> float:
        return self.settings.friction

    def simulator(self, vertices: np.ndarray | None = None):
        """A ClothSimulator of this scene starting at `vertices` (default: flat), rest = flat."""
        from .simulator import ClothSimulator

        start = self.flat if vertices is None else vertices
        return ClothSimulator(start, self.garment.triangles, self.material, self.friction, self.config,
                              rest=self.flat)


def build_scene(settings: SceneSettings) -> Scene:
    """Mesh the garment and lay it flat: the scene of `settings`."""
    mat = material(settings.material)
    garment = make_shirt(settings.shape, max_area=settings.max_area)
    return Scene(settings, garment, mat, flat_start(garment, mat), settings.config())
