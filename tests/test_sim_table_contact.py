"""The table contact in closed form equals ipctk's vertex-plane potentials."""
from __future__ import annotations

import ipctk
import numpy as np

from clothfold_ros.sim.table_contact import TableContact
from sim_helpers import rectangle

XI = DHAT = 3.18e-4
KAPPA, MU, EPS = 7.3, 0.5, 4e-5
PSD = ipctk.PSDProjectionMethod.CLAMP


def _plane_collisions(mesh, x):
    cand = ipctk.Candidates()
    cand.build(mesh, np.asfortranarray(x), np.asfortranarray(x), XI + DHAT)
    col = ipctk.NormalCollisions()
    col.build(cand, mesh, np.asfortranarray(x), DHAT, XI)
    assert {type(col[i]).__name__ for i in range(len(col))} == {"PlaneVertexNormalCollision"}
    return col


def test_table_contact_matches_ipctk_vertex_plane_potentials():
    rng = np.random.default_rng(3)
    rest, tri = rectangle(0.04, 0.04, 1e-5, 0.0)
    n = len(rest)
    x = rest.copy()
    x[:, 2] = XI * (1.0 + rng.uniform(0.001, 2.5, n))  # some within the barrier's range, some beyond
    x_prev = x.copy()
    x_prev[:, 2] = XI * (1.0 + rng.uniform(0.001, 1.5, n))
    u = np.zeros_like(x)
    u[:, :2] = rng.normal(scale=EPS, size=(n, 2))  # sticking and sliding displacements
    u[: n // 10] = 0.0  # at rest

    # ipctk: the table as a collision-mesh plane; friction lagged at x_prev, potentials at x
    mesh = ipctk.CollisionMesh(np.asfortranarray(rest), ipctk.edges(tri), tri)
    mesh.planes = [ipctk.Hyperplane(np.array([0.0, 0.0, 1.0]), np.zeros(3))]
    barrier = ipctk.BarrierPotential(DHAT, KAPPA)
    lagged, col = _plane_collisions(mesh, x_prev), _plane_collisions(mesh, x)
    tangential = ipctk.TangentialCollisions()
    tangential.build(mesh, np.asfortranarray(x_prev), lagged, barrier, MU)
    friction = ipctk.FrictionPotential(EPS)
    xf, uf = np.asfortranarray(x), np.asfortranarray(u)
    e_ref = barrier(col, mesh, xf) + friction(tangential, mesh, uf)
    g_ref = barrier.gradient(col, mesh, xf) + friction.gradient(tangential, mesh, uf)
    h_ref = (barrier.hessian(col, mesh, xf, PSD) + friction.hessian(tangential, mesh, uf, PSD)).toarray()

    table = TableContact(XI, DHAT, MU, EPS)
    table.lag_friction(x_prev, KAPPA)
    assert len(lagged) > 20 and len(col) > 20
    assert np.isclose(table.energy(x, u, KAPPA), e_ref, rtol=1e-10, atol=0)
    assert np.allclose(table.gradient(x, u, KAPPA), g_ref, rtol=1e-9, atol=1e-12 * np.abs(g_ref).max())
    ids, blocks = table.hessian_blocks(x, u, KAPPA)
    h = np.zeros((3 * n, 3 * n))
    r, c = np.triu_indices(3)
    for i, b in zip(ids, blocks):
        h[3 * i + r, 3 * i + c] = b
        h[3 * i + c, 3 * i + r] = b
    assert np.allclose(h, h_ref, rtol=1e-9, atol=1e-12 * np.abs(h_ref).max())
    assert table.count(x) == len(col)
    assert np.isclose(table.min_distance(x), np.sqrt(col.compute_minimum_distance(mesh, xf)))
    below = x.copy()
    below[0, 2] = 0.5 * XI  # inside the offset: the barrier is undefined there
    assert table.energy(below, u, KAPPA) == np.inf
