"""Cloth in frictional contact keeps its momentum as Coulomb friction says (docs/simulator.md, "Sticking").

A square of cotton resting on the table is given a horizontal velocity. Implicit Euler
with friction lagged at the step's start takes mu g dt off the speed per step (the table
carries the cloth's weight), so the cloth slides dt * sum of the speeds at the ends of the
steps. The Newton solve used to stop at its first iterate (the cloth where it was): the
smoothed static friction's curvature is so stiff that the first Newton step was shorter
than the step-size tolerance, and the cloth stopped dead (0 mm here). The same check on
the resting cloth: the table must carry its weight, not half of it.
"""
from __future__ import annotations

import numpy as np
import pytest

from clothfold_ros.materials import material
from clothfold_ros.sim.config import SimConfig
from clothfold_ros.sim.friction import table_normal_forces
from clothfold_ros.sim.simulator import ClothSimulator

from sim_helpers import rectangle

GRAVITY = 9.81


def _discrete_slide(v0: float, mu: float, dt: float, steps: int) -> float:
    """Distance (m) that implicit Euler with per-step lagged Coulomb friction slides."""
    v, d = v0, 0.0
    for _ in range(steps):
        v = max(0.0, v - mu * GRAVITY * dt)
        d += dt * v
    return d


def _rested(mu: float) -> ClothSimulator:
    v, tri = rectangle(0.2, 0.2, 3e-4, 2 * material("cotton").thickness)  # 20 cm square, flat at z = 2 t
    sim = ClothSimulator(v, tri, material("cotton"), mu, SimConfig())
    for _ in range(8):  # 0.32 s: fall into the barrier's range and come to rest
        sim.step()
    return sim


@pytest.mark.parametrize("mu", [0.5, 0.2])
def test_sliding_cloth_travels_the_coulomb_distance(mu):
    sim = _rested(mu)
    x0 = sim.x.copy()
    sim.v[:, 0] = 0.5
    steps = 10
    for _ in range(steps):
        sim.step()
    slid = float(np.mean(sim.x[:, 0] - x0[:, 0]))
    expected = _discrete_slide(0.5, mu, sim.dt, steps)
    assert slid == pytest.approx(expected, rel=0.05), f"slid {slid * 1e3:.2f} mm, Coulomb {expected * 1e3:.2f} mm"
    assert np.abs(sim.v).max() < 1e-3  # and it has come to rest


def test_resting_cloth_is_carried_by_the_table():
    sim = _rested(0.5)
    c = sim.contact
    _, forces = table_normal_forces(sim.x[:, 2], c.kappa, c.xi, c.dhat)
    carried = forces.sum() / sim.dt**2  # the barrier's forces are in the incremental potential's units (x dt^2)
    weight = sim.vertex_mass.sum() * GRAVITY
    assert carried == pytest.approx(weight, rel=0.05)
