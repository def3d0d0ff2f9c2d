"""Subspace Newton directions: the principal subsystem of the moving vertices (sim/subspace.py)
and the simulator's use of it (SimConfig.subspace_threshold)."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from clothfold_ros.materials import MATERIALS
from clothfold_ros.sim import ClothSimulator, SimConfig
from clothfold_ros.sim.pattern import HessianPattern, element_dofs
from clothfold_ros.sim.subspace import active_vertices, subsystem
from sim_helpers import rectangle


def _pattern_with_contacts(seed: int = 0):
    v, f = rectangle(0.03, 0.02, 2e-5, 0.0)
    pat = HessianPattern(3 * len(v), [element_dofs(f)], f)
    rng = np.random.default_rng(seed)
    pairs = rng.integers(0, len(v), size=(40, 2))  # far-apart "contact" blocks grow the pattern
    rows = np.concatenate([3 * pairs[:, 0:1] + np.arange(3), 3 * pairs[:, 1:2] + np.arange(3)], axis=1)
    r = np.repeat(rows, 6, axis=1).ravel()
    c = np.tile(rows, (1, 6)).ravel()
    pat.contact_slots(sp.coo_matrix((np.ones(len(r)), (r, c)), shape=(pat.ndof, pat.ndof)).tocsc())
    return v, pat, rng


def test_subsystem_is_the_principal_submatrix_of_the_active_vertices():
    v, pat, rng = _pattern_with_contacts()
    data = rng.normal(size=9 * pat.nnz)
    upper = pat.matrix(data).toarray()
    full = np.triu(upper) + np.triu(upper, 1).T
    active = rng.random(len(v)) < 0.3
    sub = subsystem(pat.block_rows, pat.indices, active)
    assert np.array_equal(sub.vertices, np.flatnonzero(active))
    n = 3 * len(sub.vertices)
    blocks = sp.bsr_matrix((sub.values(data).reshape(-1, 3, 3), sub.indices, sub.indptr), shape=(n, n)).toarray()
    mine = np.triu(blocks) + np.triu(blocks, 1).T
    assert np.array_equal(mine, full[np.ix_(sub.dofs, sub.dofs)])
    assert np.array_equal(sub.values(data)[sub.diag_slots], np.diag(full)[sub.dofs])


def test_active_vertices_are_the_moving_ones_grown_by_rings_of_the_pattern():
    v, pat, _ = _pattern_with_contacts()
    step = np.zeros((len(v), 3))
    step[7] = [0.0, 2e-3, 0.0]
    step[9] = [1e-5, 0.0, 0.0]  # below the threshold
    assert np.array_equal(np.flatnonzero(active_vertices(step, 1e-4, pat.block_rows, pat.indices, 0)), [7])
    one_ring = active_vertices(step, 1e-4, pat.block_rows, pat.indices, 1)
    upper = pat.matrix(np.ones(9 * pat.nnz)).toarray()
    neighbours = np.flatnonzero((np.abs(upper[3 * 7]) + np.abs(upper[:, 3 * 7]))[::3] > 0)
    assert np.array_equal(np.flatnonzero(one_ring), neighbours)
    two_rings = active_vertices(step, 1e-4, pat.block_rows, pat.indices, 2)
    assert one_ring.sum() < two_rings.sum() and not (one_ring & ~two_rings).any()


def _drape(threshold: float, steps: int = 8):
    """A strip lying on the table with its last fifth raised: that end falls while the rest
    stays (the situation of a fold's late Newton iterations)."""
    cotton = MATERIALS["cotton"]
    v, f = rectangle(0.1, 0.02, 4e-6, 2.0 * cotton.thickness)
    v[:, 2] += 2.0 * np.maximum(v[:, 0] - 0.08, 0.0)  # up to 4 cm at the far end
    sim = ClothSimulator(v, f, cotton, 0.5, SimConfig(subspace_threshold=threshold))
    stats = [sim.step() for _ in range(steps)]
    return sim, stats


def test_subspace_newton_converges_on_all_vertices_and_matches_full_newton():
    full, full_stats = _drape(0.0)
    sub, sub_stats = _drape(1e-4)
    assert full.subspace_solves == 0 and sub.subspace_solves > 0
    tol = SimConfig().newton_tol
    assert all(s.residual <= tol for s in sub_stats)  # every step ends on a full direction below tol
    # Both stop within the Newton tolerance of the same solution: under one tol x dt apart.
    gap = np.linalg.norm(sub.x - full.x, axis=1).max()
    assert gap < tol * SimConfig().dt, gap
    assert gap > 0.0  # a different Newton path (the subspace solves did something)


def test_subspace_settings_are_validated():
    for bad in (dict(subspace_threshold=-1.0), dict(subspace_start=0), dict(subspace_rings=-1),
                dict(subspace_max_share=0.0), dict(subspace_max_share=1.5)):
        with pytest.raises(ValueError, match="subspace"):
            SimConfig(**bad)


def test_elements_touching_the_subsystem_assemble_its_block_and_gradient_exactly():
    """The triangles and hinges touching the active vertices give the subsystem's rows of
    the Newton matrix and gradient bit for bit (the simulator evaluates only them)."""
    from clothfold_ros.sim import bending, membrane
    from clothfold_ros.sim.pattern import scatter_gradient
    from clothfold_ros.sim.subspace import element_subset

    cotton = MATERIALS["cotton"]
    v, f = rectangle(0.03, 0.02, 2e-5, 0.0)
    hinges = bending.hinges(f)
    pat = HessianPattern(3 * len(v), [element_dofs(f), element_dofs(hinges)], f)
    rng = np.random.default_rng(1)
    x = v + 1e-3 * rng.normal(size=v.shape)
    shape, area = membrane.rest_shape(v, f)
    theta, weight = bending.rest_state(v, hinges)
    lam, mu = cotton.lame

    def derivatives(t, k):
        _, gm, hm = membrane.membrane_derivatives(x, f[t], shape[t], area[t] * cotton.thickness, lam, mu,
                                                  membrane.PROJECT_CLAMP, True)
        _, gb, hb = bending.bending_derivatives(x, hinges[k], theta[k], weight[k], cotton.bending_stiffness, True)
        g = scatter_gradient(pat.ndof, element_dofs(f[t]), gm) + scatter_gradient(pat.ndof, element_dofs(hinges[k]), gb)
        return g, [hm, hb]

    active = rng.random(len(v)) < 0.2
    sub = subsystem(pat.block_rows, pat.indices, active)
    part = element_subset(active, f, hinges, pat.block_slots)
    assert not active[f[np.setdiff1d(np.arange(len(f)), part.triangles)]].any()
    g_all, h_all = derivatives(slice(None), slice(None))
    g_sub, h_sub = derivatives(part.triangles, part.hinges)
    diag = np.ones(pat.ndof)
    full = pat.assemble(h_all, 1.0, diag)
    mine = pat.assemble(h_sub, 1.0, diag, element_slots=part.block_slots)
    assert np.array_equal(sub.values(mine), sub.values(full))
    assert np.array_equal(g_sub[sub.dofs], g_all[sub.dofs])
    assert not np.array_equal(mine, full)  # the other blocks were left out


def test_subspace_follows_a_pattern_that_grows_within_an_iteration(monkeypatch):
    """Contact blocks that join the pattern in a subspace iteration (after its elements were
    chosen) renumber the blocks: the subsystem is rebuilt before the solve, so the run still
    matches full Newton. The growth is forced: every contact Hessian brings a new (zero)
    block between two far-apart vertices."""
    from clothfold_ros.sim.contact import ContactModel

    real = ContactModel.hessian
    calls = {"n": 0}

    def growing(self, col, x):
        h = real(self, col, x)
        n = len(x)
        i, j = calls["n"] % (n // 2), n - 1 - calls["n"] % (n // 2)
        calls["n"] += 1
        dofs = (3 * np.array([i, j])[:, None] + np.arange(3)).ravel()
        spring = 1e-30 * np.kron(np.array([[1.0, -1.0], [-1.0, 1.0]]), np.eye(3))  # PSD, negligible
        extra = sp.coo_matrix((spring.ravel(), (np.repeat(dofs, 6), np.tile(dofs, 6))), shape=(3 * n, 3 * n))
        return extra.tocsc() if h is None else (h + extra).tocsc()

    monkeypatch.setattr(ContactModel, "hessian", growing)

    def run(threshold: float):
        cotton = MATERIALS["cotton"]
        v, f = rectangle(0.1, 0.02, 4e-6, 2.0 * cotton.thickness)
        v[:, 2] += 2.0 * np.maximum(v[:, 0] - 0.08, 0.0)
        sim = ClothSimulator(v, f, cotton, 0.5, SimConfig(subspace_threshold=threshold, pattern_growth_iterations=400))
        versions = []
        for _ in range(4):
            sim.step()
            versions.append(sim._pattern.version)
        return sim, versions

    full, _ = run(0.0)
    sub, versions = run(1e-4)
    assert sub.subspace_solves > 0 and versions[-1] > sub.subspace_solves  # it grew in subspace iterations too
    assert np.linalg.norm(sub.x - full.x, axis=1).max() < SimConfig().newton_tol * SimConfig().dt


def test_a_newton_tolerance_below_the_subspace_threshold_solves_whole_systems():
    """With tol < threshold a full step above tol can have no vertex above the threshold: that
    empty subsystem is solved whole (it made PARDISO's analysis fail in a tight reference)."""
    cotton = MATERIALS["cotton"]
    v, f = rectangle(0.1, 0.02, 4e-6, 2.0 * cotton.thickness)
    v[:, 2] += 2.0 * np.maximum(v[:, 0] - 0.08, 0.0)
    cfg = SimConfig(newton_tol=1e-6, subspace_threshold=1e-4, max_newton_iterations=3000)
    sim = ClothSimulator(v, f, cotton, 0.5, cfg)
    stats = [sim.step() for _ in range(3)]
    assert all(s.residual <= 1e-6 for s in stats)
