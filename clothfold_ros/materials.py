"""Cloth materials (Penava et al. 2014, docs/method.md section 2) and contact friction.

Units: Young's modulus in Pa, areal density in kg/m^2, thickness in m.
"""
from __future__ import annotations

import math

from dataclasses import dataclass, replace


@dataclass(frozen=True)
class Material:
    """An isotropic thin-shell cloth material."""

    name: str
    youngs_modulus: float  # Pa
    poisson_ratio: float  # -
    areal_density: float  # kg/m^2
    thickness: float  # m

    def __post_init__(self) -> None:
        values = (self.youngs_modulus, self.areal_density, self.thickness)
        if not all(math.isfinite(v) and v > 0 for v in values):
            raise ValueError(f"material {self.name!r}: modulus, density and thickness must be finite and > 0")
        if not (0.0 <= self.poisson_ratio < 0.5):
            raise ValueError(f"material {self.name!r}: Poisson ratio must be in [0, 0.5)")

    @property
    def lame(self) -> tuple[float, float]:
        """Plane-stress Lame parameters (lambda, mu) in Pa."""
        e, nu = self.youngs_modulus, self.poisson_ratio
        return e * nu / (1.0 - nu * nu), e / (2.0 * (1.0 + nu))

    @property
    def bending_stiffness(self) -> float:
        """Hinge bending stiffness k = E t^3 / (24 (1 - nu^2)) in N m."""
        e, nu, t = self.youngs_modulus, self.poisson_ratio, self.thickness
        return e * t**3 / (24.0 * (1.0 - nu * nu))


_COTTON = Material("cotton", 0.821e6, 0.243, 0.1503, 0.318e-3)

MATERIALS: dict[str, Material] = {
    "cotton": _COTTON,
    "wool": Material("wool", 0.170e6, 0.277, 0.2348, 0.568e-3),
    "polyester": Material("polyester", 0.478e6, 0.381, 0.1646, 0.252e-3),
    # Thin / thick cotton: thickness / 5 and x 5, everything else (mass too) unchanged.
    "thin_cotton": replace(_COTTON, name="thin_cotton", thickness=_COTTON.thickness / 5),
    "thick_cotton": replace(_COTTON, name="thick_cotton", thickness=_COTTON.thickness * 5),
}

DEFAULT_FRICTION = 0.5
FRICTION_VARIANTS = (0.2, 0.5, 0.8)


def material(name: str) -> Material:
    """Look a material preset up by name, with a clear error for unknown names."""
    try:
        return MATERIALS[name]
    except KeyError:
        raise ValueError(f"unknown material {name!r}; known: {', '.join(MATERIALS)}") from None
