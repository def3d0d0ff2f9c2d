"""Element kernels and assembly of the simulator against finite differences and dense sums."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from clothfold_ros.sim import bending, membrane
from clothfold_ros.sim.linear_solver import spd_solver
from clothfold_ros.sim.pattern import HessianPattern, element_dofs, scatter_gradient
from sim_helpers import rectangle

EPS = 1e-6


def test_membrane_gradient_and_hessian_match_finite_differences():
    rest = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]])
    tri = np.array([[0, 1, 2]])
    b, area = membrane.rest_shape(rest, tri)
    vol = area * 0.01
    x = rest * 1.3 + np.random.default_rng(1).normal(0, 0.1, (3, 3))  # stretched: PSD region
    e, g, h = membrane.membrane_derivatives(x, tri, b, vol, 2.0, 3.0)
    fd_g, fd_h = np.zeros(9), np.zeros((9, 9))
    for i in range(9):
        xp, xm = x.copy(), x.copy()
        xp.flat[i] += EPS
        xm.flat[i] -= EPS
        fd_g[i] = (membrane.membrane_energy(xp, tri, b, vol, 2.0, 3.0) - membrane.membrane_energy(xm, tri, b, vol, 2.0, 3.0)) / (2 * EPS)
        fd_h[:, i] = (membrane.membrane_derivatives(xp, tri, b, vol, 2.0, 3.0)[1][0] - membrane.membrane_derivatives(xm, tri, b, vol, 2.0, 3.0)[1][0]) / (2 * EPS)
    assert np.allclose(g[0], fd_g, atol=1e-8)
    assert np.linalg.eigvalsh(fd_h).min() > -1e-8  # this state is convex, so projection is a no-op
    assert np.allclose(h[0], fd_h, atol=1e-7)


def test_membrane_rest_energy_is_zero_and_projection_is_psd():
    v, f = rectangle(0.1, 0.1, 5e-4, 0.0)
    b, area = membrane.rest_shape(v, f)
    e0, g0, _ = membrane.membrane_derivatives(v, f, b, area * 1e-3, 2e5, 3e5)
    assert abs(e0) < 1e-12 and np.abs(g0).max() < 1e-9
    x = v + np.random.default_rng(0).normal(0, 2e-3, v.shape)  # compressed and sheared
    _, _, h = membrane.membrane_derivatives(x, f, b, area * 1e-3, 2e5, 3e5)
    assert min(np.linalg.eigvalsh(hi).min() for hi in h) > -1e-9


def test_dihedral_angle_gradient_matches_finite_differences():
    x = np.array([[0, 0, 0], [1, 0, 0], [0.3, 0.8, 0.1], [0.6, -0.7, 0.3]], float)
    h = np.array([[0, 1, 2, 3]])
    g = np.empty(12)
    bending._hinge_into(x, 0, 1, 2, 3, g)
    fd = np.zeros(12)
    for i in range(12):
        xp, xm = x.copy(), x.copy()
        xp.flat[i] += EPS
        xm.flat[i] -= EPS
        fd[i] = (bending.dihedral_angles(xp, h)[0] - bending.dihedral_angles(xm, h)[0]) / (2 * EPS)
    assert np.allclose(g, fd, atol=1e-8)


def test_flat_mesh_hinges_are_flat_and_interior():
    v, f = rectangle(0.1, 0.1, 5e-4, 0.0)
    h = bending.hinges(f)
    n_edges = len({tuple(sorted(e)) for t in f for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))})
    n_boundary = n_edges - len(h)
    assert len(h) > 0 and n_boundary > 0
    assert np.allclose(bending.dihedral_angles(v, h), 0.0)


def _fd_hessian(x, tri, b, vol, lam, mu):
    fd = np.zeros((9, 9))
    for i in range(9):
        xp, xm = x.copy(), x.copy()
        xp.flat[i] += EPS
        xm.flat[i] -= EPS
        gp = membrane.membrane_derivatives(xp, tri, b, vol, lam, mu, membrane.PROJECT_NONE)[1][0]
        gm = membrane.membrane_derivatives(xm, tri, b, vol, lam, mu, membrane.PROJECT_NONE)[1][0]
        fd[:, i] = (gp - gm) / (2 * EPS)
    return fd


def test_membrane_closed_form_eigensystem_is_the_exact_hessian_in_compression():
    """The analytic eigensystem reproduces the exact Hessian (indefinite states included)
    and its projections are PSD and keep the non-negative part of the spectrum."""
    rest = np.array([[0, 0, 0], [1, 0, 0], [0.2, 0.9, 0.0]])
    tri = np.array([[0, 1, 2]])
    b, area = membrane.rest_shape(rest, tri)
    vol = area * 0.01
    rng = np.random.default_rng(3)
    indefinite = 0
    for _ in range(60):
        x = rest * rng.uniform(0.6, 1.1) + rng.normal(0, 0.15, (3, 3))
        e, _, h = membrane.membrane_derivatives(x, tri, b, vol, 2.0, 3.0, membrane.PROJECT_NONE)
        if not np.isfinite(e):
            continue
        fd = _fd_hessian(x, tri, b, vol, 2.0, 3.0)
        assert np.allclose(h[0], fd, atol=1e-6 * np.abs(fd).max())
        w = np.linalg.eigvalsh(fd)
        indefinite += w.min() < -1e-6 * np.abs(w).max()
        for method in (membrane.PROJECT_CLAMP, membrane.PROJECT_ABS):
            hp = membrane.membrane_derivatives(x, tri, b, vol, 2.0, 3.0, method)[2][0]
            wp = np.linalg.eigvalsh(hp)
            assert wp.min() > -1e-9 * np.abs(wp).max()
            assert wp.max() >= w.max() * (1 - 1e-6)
    assert indefinite > 10  # the check covered compressed (indefinite) states


def test_hessian_pattern_assembles_the_dense_sum_and_grows_for_contacts():
    v, f = rectangle(0.05, 0.05, 5e-4, 0.0)
    n = 3 * len(v)
    h = bending.hinges(f)
    blocks = [element_dofs(f), element_dofs(h)]
    pat = HessianPattern(n, blocks)
    rng = np.random.default_rng(0)
    he = rng.normal(size=(len(f), 9, 9))
    he = he + he.transpose(0, 2, 1)
    hh = rng.normal(size=(len(h), 12, 12))
    hh = hh + hh.transpose(0, 2, 1)
    diag = rng.normal(size=n)
    dense = np.diag(diag)
    for dofs, hs in zip(blocks, (he, hh)):
        for d, m in zip(dofs, hs):
            dense[np.ix_(d, d)] += 0.5 * m
    data = pat.assemble([he, hh], 0.5, diag)
    upper = pat.matrix(data).toarray()
    assert np.allclose(upper, np.triu(dense))
    s = rng.uniform(0.5, 2.0, size=n)  # the diagonal scaling the simulator factorizes with
    assert np.allclose(pat.matrix(pat.scaled(data, s)).toarray(), np.triu(s[:, None] * dense * s[None, :]))
    # a contact between two far-apart vertices is outside the elastic pattern: it grows
    a, c = 0, len(v) - 1
    dofs = np.r_[3 * a : 3 * a + 3, 3 * c : 3 * c + 3]
    block = rng.normal(size=(6, 6))
    block = block @ block.T
    hc = np.zeros((n, n))
    hc[np.ix_(dofs, dofs)] = block
    version, nnz = pat.version, pat.nnz
    slots, vals, grew = pat.contact_slots(sp.csc_matrix(hc))
    assert grew and pat.version == version + 1 and pat.nnz > nnz
    full = pat.matrix(pat.assemble([he, hh], 0.5, diag, (slots, vals))).toarray()
    assert np.allclose(full, np.triu(dense + hc))
    # the same contact again: no growth, same pattern
    assert not pat.contact_slots(sp.csc_matrix(hc))[2]
    g = rng.normal(size=(len(f), 9))
    ref = np.zeros(n)
    for d, gi in zip(blocks[0], g):
        ref[d] += gi
    assert np.allclose(scatter_gradient(n, blocks[0], g), ref)


def _reference_slots(pat: HessianPattern, h: sp.csc_matrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Value slots (-2: block missing), values and block keys of the upper-block entries of h, in
    storage order, by a sorted search over the pattern's block keys."""
    coo = h.tocoo()
    r, c = coo.row.astype(np.int64), coo.col.astype(np.int64)
    keep = r // 3 <= c // 3
    keys = (r // 3 * pat.nv + c // 3)[keep]
    pos = np.searchsorted(pat.keys, keys)
    present = pat.keys[np.minimum(pos, pat.nnz - 1)] == keys
    return np.where(present, 9 * pos + (3 * (r % 3) + c % 3)[keep], -2), coo.data[keep], keys


def test_contact_slots_match_a_sorted_search_and_bump_missing_blocks():
    """contact_slots (one pass over a CSC Hessian's stored entries) gives, in storage order, the
    slots a sorted search over the block keys gives; missing blocks are deferred with their
    Frobenius norms on both vertices' diagonals (grow=False) or added (grow=True)."""
    v, f = rectangle(0.05, 0.05, 5e-4, 0.0)
    n = 3 * len(v)
    rng = np.random.default_rng(7)
    dofs = element_dofs(rng.integers(0, len(v), size=(40, 4)))
    local = rng.normal(size=(40, 12, 12))
    rows, cols = np.repeat(dofs, 12, axis=1).ravel(), np.tile(dofs, (1, 12)).ravel()
    hc = sp.coo_matrix(((local + local.transpose(0, 2, 1)).ravel(), (rows, cols)), shape=(n, n)).tocsc()

    pat = HessianPattern(n, [element_dofs(f)])
    pat.begin_solve()
    ref, vals, keys = _reference_slots(pat, hc)
    miss = ref == -2
    assert miss.any() and (~miss).any()
    slots, got, grew = pat.contact_slots(hc, grow=False)
    uniq = np.unique(keys[miss])
    norm = np.array([np.sqrt(np.sum(vals[miss][keys[miss] == k] ** 2)) for k in uniq])
    bump = np.zeros(pat.nv)
    np.add.at(bump, uniq // pat.nv, norm)
    np.add.at(bump, uniq % pat.nv, norm)
    assert not grew and np.array_equal(pat.pending, uniq)
    assert np.array_equal(slots, np.concatenate([ref[~miss], pat.diag_slots]))
    assert np.array_equal(got[:np.count_nonzero(~miss)], vals[~miss])
    assert np.allclose(got[np.count_nonzero(~miss):], np.repeat(bump, 3))
    assert pat.begin_solve()  # the deferred blocks are added
    slots, got, grew = pat.contact_slots(hc)
    ref, vals, _ = _reference_slots(pat, hc)
    assert not grew and (ref >= 0).all() and np.array_equal(slots, ref) and np.array_equal(got, vals)

    fresh = HessianPattern(n, [element_dofs(f)])
    fresh.begin_solve()
    slots, got, grew = fresh.contact_slots(hc)  # grow=True: added at once
    ref, vals, _ = _reference_slots(fresh, hc)
    assert grew and (ref >= 0).all() and np.array_equal(slots, ref) and np.array_equal(got, vals)
    assert (fresh.last_used[slots // 9] == fresh.solves).all()
    assert np.array_equal(fresh.keys, pat.keys)

    # entries as a CSC matrix may hold them: rows unsorted within a column, duplicates, int64 indices
    order = np.concatenate([rng.permutation(np.arange(a, b)) for a, b in zip(hc.indptr[:-1], hc.indptr[1:])])
    dup = np.repeat(np.arange(hc.shape[1]), np.diff(hc.indptr))  # column of each entry
    twice = np.concatenate([order, order[:50]])  # 50 entries stored twice, appended to their columns below
    cols = np.concatenate([dup[order], dup[order[:50]]])
    keep_order = np.argsort(cols, kind="stable")
    raw = sp.csc_matrix((hc.data[twice][keep_order], hc.indices[twice][keep_order].astype(np.int64),
                         np.searchsorted(cols[keep_order], np.arange(n + 1)).astype(np.int64)), shape=(n, n))
    assert not raw.has_canonical_format
    slots, got, grew = fresh.contact_slots(raw)
    ref, vals, _ = _reference_slots(fresh, raw)
    assert not grew and np.array_equal(slots, ref) and np.array_equal(got, vals)
    empty = fresh.contact_slots(sp.csc_matrix((n, n)))
    assert len(empty[0]) == len(empty[1]) == 0 and not empty[2]


def test_hessian_pattern_prunes_contact_entries_unused_for_keep_solves():
    v, f = rectangle(0.05, 0.05, 5e-4, 0.0)
    n = 3 * len(v)
    pat = HessianPattern(n, [element_dofs(f)], keep_solves=2, prune_fraction=0.25)
    rng = np.random.default_rng(2)
    he = rng.normal(size=(len(f), 9, 9))
    he = he + he.transpose(0, 2, 1)
    diag = rng.normal(size=n)
    base = pat.matrix(pat.assemble([he], 1.0, diag)).toarray()

    def contact(a, c):
        dofs = np.r_[3 * a : 3 * a + 3, 3 * c : 3 * c + 3]
        hc = np.zeros((n, n))
        hc[np.ix_(dofs, dofs)] = np.eye(6) + 0.1
        return hc

    old, kept = contact(0, len(v) - 1), contact(1, len(v) - 2)
    pat.begin_solve()
    pat.contact_slots(sp.csc_matrix(old + kept))
    grown = pat.nnz
    for _ in range(2):  # `old` separates; `kept` stays in contact
        assert not pat.begin_solve()
        pat.contact_slots(sp.csc_matrix(kept))
    version = pat.version
    assert pat.begin_solve() and pat.version > version  # `old` unused for more than 2 solves: dropped
    assert base.size and pat.nnz < grown
    slots, vals, grew = pat.contact_slots(sp.csc_matrix(kept))
    assert not grew  # the entries still in use kept their slots
    full = pat.matrix(pat.assemble([he], 1.0, diag, (slots, vals))).toarray()
    assert np.allclose(full, base + np.triu(kept))
    assert np.allclose(pat.matrix(pat.assemble([he], 1.0, diag)).toarray(), base)  # element blocks intact


def _block_system(width: float, seed: int, psd: bool):
    """A width x width rectangle's element pattern with random 9x9 element blocks (PSD or symmetric)."""
    v, f = rectangle(width, width, 5e-4, 0.0)
    pat = HessianPattern(3 * len(v), [element_dofs(f)])
    rng = np.random.default_rng(seed)
    he = rng.normal(size=(len(f), 9, 9))
    he = np.einsum("eij,ekj->eik", he, he) if psd else he + he.transpose(0, 2, 1)
    return pat, he, rng


def _full(pat: HessianPattern, data: np.ndarray) -> np.ndarray:
    upper = pat.matrix(data)
    return (upper + sp.triu(upper, k=1).T).toarray()


def test_spd_solvers_solve_on_the_persistent_pattern():
    pat, he, rng = _block_system(0.05, 1, psd=True)
    n = pat.ndof
    rhs = rng.normal(size=n)
    for backend, precision in (("pardiso", "mixed"), ("pardiso", "double"), ("superlu", "double")):
        solver = spd_solver(backend, precision=precision)
        solver.set_pattern(pat.indptr, pat.indices, pat.block)
        for scale in (1.0, 2.0):  # refactor on the same pattern: analysed once
            data = pat.assemble([he], scale, np.ones(n))
            solver.factor(data)
            x = solver.solve(rhs)
            # mixed: refined in double to a relative residual of 1e-8; double: a direct solve
            tol = 1e-8 if precision == "mixed" else 1e-12
            assert np.linalg.norm(_full(pat, data) @ x - rhs) <= tol * np.linalg.norm(rhs)
        assert solver.analyses == (1 if backend == "pardiso" else 2)
        assert solver.fallbacks == 0
        if precision == "mixed":
            assert solver.refinements >= 1  # single precision alone does not reach 1e-8 here


def test_symmetric_matvec_of_the_upper_block_triangle():
    from clothfold_ros.sim.linear_solver import symmetric_block_matvec

    pat, he, rng = _block_system(0.03, 2, psd=False)
    data = pat.assemble([he], 1.0, rng.normal(size=pat.ndof))
    full = _full(pat, data)
    x = rng.normal(size=pat.ndof)
    assert np.allclose(symmetric_block_matvec(pat.indptr, pat.indices, data, 3, x), full @ x, rtol=1e-12, atol=1e-12)
    csr = sp.csr_matrix(np.triu(full))  # the same matrix entry by entry (block 1)
    y = symmetric_block_matvec(csr.indptr.astype(np.int32), csr.indices.astype(np.int32), csr.data, 1, x)
    assert np.allclose(y, full @ x, rtol=1e-12, atol=1e-12)
    import pytest

    with pytest.raises(ValueError, match="block must be 1 or 3"):
        symmetric_block_matvec(pat.indptr, pat.indices, data, 2, x)


def test_mixed_precision_falls_back_to_double_where_single_precision_fails():
    """An SPD matrix that is singular in single precision: [[1, 1 - 1e-9], [1 - 1e-9, 1]]
    (1 - 1e-9 rounds to 1 in float32) plus a well-conditioned third unknown."""
    c = 1.0 - 1e-9
    full = np.array([[1.0, c, 0.0], [c, 1.0, 0.0], [0.0, 0.0, 2.0]])
    upper = sp.csr_matrix(np.triu(full))
    solver = spd_solver("pardiso", precision="mixed")
    solver.set_pattern(upper.indptr.astype(np.int32), upper.indices.astype(np.int32), 1)
    solver.factor(upper.data)
    rhs = np.array([1.0, -1.0, 2.0])
    x = solver.solve(rhs)
    assert solver.fallbacks == 1
    assert np.allclose(x, np.linalg.solve(full, rhs), rtol=1e-6)


def test_solver_and_settings_reject_bad_block_rhs_and_thread_counts():
    import pytest

    from clothfold_ros.sim.config import SimConfig

    v, f = rectangle(0.02, 0.02, 5e-4, 0.0)
    pat = HessianPattern(3 * len(v), [element_dofs(f)])
    solver = spd_solver("pardiso")
    with pytest.raises(ValueError, match="block must be >= 1"):
        solver.set_pattern(pat.indptr, pat.indices, 0)
    solver.set_pattern(pat.indptr, pat.indices, pat.block)
    solver.factor(pat.assemble([np.zeros((len(f), 9, 9))], 1.0, np.ones(3 * len(v))))
    with pytest.raises(ValueError, match="right-hand side must have"):
        solver.solve(np.ones(3 * len(v) - 1))
    with pytest.raises(ValueError, match="multiple of 3"):
        HessianPattern(3 * len(v) + 1, [element_dofs(f)])
    for bad in (dict(ccd_threads=0), dict(solver_threads=0), dict(threads=0)):
        with pytest.raises(ValueError, match="must be >= 1"):
            SimConfig(**bad)
    with pytest.raises(ValueError, match="pattern_growth_iterations"):
        SimConfig(pattern_growth_iterations=0)
    for bad in ((1e-6, 1e-8), (0.0,), (-1.0,)):
        with pytest.raises(ValueError, match="regularization_shifts"):
            SimConfig(regularization_shifts=bad)


def test_lagged_friction_kernels_equal_ipctk_friction_potential():
    """The numba friction (sim/friction.py) on a two-layer contact state (edge-edge,
    face-vertex and cloth-table contacts) gives ipctk's FrictionPotential energy, gradient
    and Hessian to rounding, in the smoothed (|u_t| < eps_v dt) and the sliding regime."""
    import ipctk

    from clothfold_ros.materials import MATERIALS
    from clothfold_ros.sim import ClothSimulator
    from clothfold_ros.sim.friction import scatter_stencil_hessians

    cotton = MATERIALS["cotton"]
    t = cotton.thickness
    v, f = rectangle(0.05, 0.05, 6e-5, 2.5 * t)
    upper = v.copy()
    upper[:, 2] += 3 * t
    upper[:, 0] += 0.01
    sim = ClothSimulator(np.vstack([v, upper]), np.vstack([f, f + len(v)]), cotton, 0.5)
    for _ in range(3):
        sim.step()
    c = sim.contact
    c.lag_friction(sim.x)
    kinds = {n: len(getattr(c.tangential, n)) for n in ("ee_collisions", "fv_collisions")}
    assert min(kinds.values()) > 10 and len(c.friction) == len(c.tangential) > sum(kinds.values())  # + table
    contacts = [cc for n in ("vv_collisions", "ev_collisions", "ee_collisions", "fv_collisions")
                for cc in getattr(c.tangential, n)]
    for cc, ids, P in zip(contacts, c.friction.ids, c.friction.P):  # read in bulk: ipctk's per-contact values
        v = np.asarray(cc.vertex_ids(c.mesh.edges, c.mesh.faces))
        assert np.array_equal(ids, np.where(v >= 0, v, -1))
        k = 3 * int(np.count_nonzero(v >= 0))
        assert np.array_equal(P[:, :k], np.asarray(cc.tangent_basis).T @ cc.relative_velocity_jacobian())
        assert not P[:, k:].any()
    reference = ipctk.FrictionPotential(c.friction.eps)
    rng = np.random.default_rng(5)
    pat = HessianPattern(sim.x.size, [element_dofs(f)])
    slots = pat.stencil_block_slots(c.friction.ids)
    for scale in (1e-6, 1e-3):  # below and beyond eps = eps_v dt = 4e-5 m
        u = rng.normal(size=sim.x.shape) * scale
        uf = np.asfortranarray(u)
        assert c.friction.energy(u) == pytest.approx(reference(c.tangential, c.mesh, uf), rel=1e-12)
        g_ref = reference.gradient(c.tangential, c.mesh, uf)
        assert np.abs(c.friction.gradient(u) - g_ref).max() <= 1e-12 * np.abs(g_ref).max()
        h_ref = reference.hessian(c.tangential, c.mesh, uf, ipctk.PSDProjectionMethod.CLAMP).toarray()
        data = np.zeros(9 * pat.nnz)
        scatter_stencil_hessians(data, slots, c.friction.hessians(u))
        assert np.abs(_full(pat, data) - h_ref).max() <= 1e-12 * np.abs(h_ref).max()


def _two_grids(offset: tuple[float, float]):
    """Two parallel 6 x 6 vertex grids 1 cm apart (the upper one shifted by `offset`, m) and
    ipctk's tangential collisions between them (dhat 2 cm, mu 0.3)."""
    import ipctk

    xs = np.linspace(0.0, 1.0, 6)
    X, Y = np.meshgrid(xs, xs)
    idx = np.arange(36).reshape(6, 6)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    f = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    lower = np.column_stack([X.ravel(), Y.ravel(), np.zeros(36)])
    upper = lower + [offset[0], offset[1], 0.01]
    v, faces = np.vstack([lower, upper]), np.vstack([f, f + 36]).astype(np.int32)
    mesh = ipctk.CollisionMesh(np.asfortranarray(v), ipctk.edges(faces), faces)
    col = ipctk.NormalCollisions()
    col.build(mesh, np.asfortranarray(v), 0.02)
    tangential = ipctk.TangentialCollisions()
    tangential.build(mesh, np.asfortranarray(v), col, ipctk.BarrierPotential(0.02, 1.0), 0.3)
    return mesh, tangential


def test_friction_lag_reads_every_contact_kind_as_ipctk_gives_it():
    """LaggedFriction.lag reads ipctk's contacts kind by kind in bulk: per contact, in the order
    vv, ev, ee, fv, then the table's, the stencil ids of ipctk's vertex_ids, P = T^T G and
    c = mu w lambda, as ipctk's per-contact accessors give them."""
    from clothfold_ros.sim.friction import LaggedFriction

    counts = dict.fromkeys(("vv_collisions", "ev_collisions", "ee_collisions", "fv_collisions"), 0)
    for offset in ((0.0, 0.0), (0.1, 0.0), (0.07, 0.04)):  # vertex over vertex, over edges, anywhere
        mesh, tangential = _two_grids(offset)
        contacts = [cc for n in counts for cc in getattr(tangential, n)]
        for n in counts:
            counts[n] += len(getattr(tangential, n))
        f = LaggedFriction(1e-4)
        f.lag(tangential, mesh, 0.3, np.array([3, 40]), np.array([0.5, 2.0]))
        assert len(f) == len(contacts) + 2 and f.ids.dtype == np.int64
        for cc, ids, P, c in zip(contacts, f.ids, f.P, f.c):
            v = np.asarray(cc.vertex_ids(mesh.edges, mesh.faces))
            k = int(np.count_nonzero(v >= 0))
            assert np.array_equal(ids, np.where(v >= 0, v, -1))
            assert np.array_equal(P[:, :3 * k], np.asarray(cc.tangent_basis).T @ cc.relative_velocity_jacobian())
            assert not P[:, 3 * k:].any() and c == 0.3 * (cc.weight * cc.normal_force_magnitude)
        assert np.array_equal(f.ids[-2:, 0], [3, 40]) and np.array_equal(f.c[-2:], 0.3 * np.array([0.5, 2.0]))
        assert (f.P[-2:, 0, 0] == 1).all() and (f.P[-2:, 1, 1] == 1).all()
    assert min(counts.values()) > 0, counts  # every kind of contact was read
    with pytest.raises(ValueError, match="table forces"):
        LaggedFriction(1e-4).lag(tangential, mesh, 0.3, np.array([3, 40]), np.array([0.5]))


def _table_friction(eps: float, force: float):
    """LaggedFriction with one cloth-table contact on vertex 0 (normal force `force`, mu 1)."""
    from types import SimpleNamespace

    from clothfold_ros.sim.friction import LaggedFriction

    f = LaggedFriction(eps)
    none = SimpleNamespace(vv_collisions=[], ev_collisions=[], ee_collisions=[], fv_collisions=[])
    f.relag = lambda: f.lag(none, SimpleNamespace(edges=None, faces=None), 1.0, np.array([0]), np.array([force]))
    f.relag()
    return f


def test_friction_contact_reversing_while_sliding_gets_the_overshoot_free_hessian():
    """Sliding (|tau| > eps) the exact Hessian has no curvature along tau; a contact whose
    tau reverses between two Newton iterations keeps c f1/y along tau for the rest of the
    step (until the next lag); one that keeps its direction keeps the exact Hessian."""
    eps, c = 1e-4, 2.0
    f = _table_friction(eps, c)
    u = np.zeros((1, 3))

    def h_xx(x: float) -> float:
        u[0, 0] = x
        return float(f.hessians(u)[0, 0, 0])

    assert h_xx(1e-3) == pytest.approx(0.0, abs=1e-9)  # sliding: exact, no curvature along tau
    assert h_xx(2e-3) == pytest.approx(0.0, abs=1e-9)  # same direction: still exact
    assert h_xx(-1e-3) == pytest.approx(c / 1e-3)  # reversed while sliding: c f1/y
    assert h_xx(5e-4) == pytest.approx(c / 5e-4)  # sticky for the step
    assert float(f.hessians(u)[0, 1, 1]) == pytest.approx(c / 5e-4)  # across tau as before
    f.relag()  # a new step: exact again
    assert not f.damped.any() and h_xx(5e-4) == pytest.approx(0.0, abs=1e-9)
    g = _table_friction(eps, c)
    u[0, 0] = 1e-3
    g.hessians(u)
    u[0, 0] = -2e-5  # reversal into the smoothed zone (|tau| < eps): not an overshoot past it
    h = g.hessians(u)[0, 0, 0]
    assert h == pytest.approx(c * (2.0 / eps - 2 * 2e-5 / eps**2))  # exact f1' there
    assert not g.damped.any()


def test_newton_system_whose_factorization_breaks_down_is_retried_with_a_diagonal_shift(monkeypatch):
    """A breakdown of the factorization is retried with SimConfig.regularization_shifts x the
    diagonal (counted per step); without shifts it is a reported failure."""
    from clothfold_ros.materials import MATERIALS
    from clothfold_ros.sim import ClothSimulator, SimConfig, SimulationFailure

    cotton = MATERIALS["cotton"]
    v, f = rectangle(0.04, 0.04, 1e-4, 0.01)
    for shifts, fails in (((1e-12, 1e-10), False), ((), True)):
        sim = ClothSimulator(v, f, cotton, 0.5, SimConfig(regularization_shifts=shifts))
        factor = sim._solver.factor

        def breaks_unshifted(data, sim=sim, factor=factor):  # the scaled system's diagonal is 1 unshifted
            if np.abs(data[sim._pattern.diag_slots] - 1.0).max() < 1e-13:
                raise np.linalg.LinAlgError("PARDISO phase 22 failed with error -4 (matrix not positive definite)")
            factor(data)

        monkeypatch.setattr(sim._solver, "factor", breaks_unshifted)
        if fails:
            with pytest.raises(SimulationFailure, match="linear solve failed"):
                sim.step()
        else:
            stats = sim.step()
            assert stats.regularized == stats.newton_iterations >= 1
            assert sim.x[:, 2].max() < 0.01  # it fell: the shifted directions are descent directions


def test_pardiso_runs_small_systems_on_one_thread_with_the_same_bits():
    """Systems below `parallel_unknowns` run on one thread (two threads were slower on the
    3K fold's systems); larger ones on the threads asked; the solution is the same bits."""
    from clothfold_ros.sim.linear_solver import PardisoSPD

    pat, he, rng = _block_system(0.1, 2, psd=True)
    n = pat.ndof
    data = pat.assemble([he], 1.0, np.ones(n))
    rhs = rng.normal(size=n)
    solutions = {}
    for limit, expected in ((n + 1, 1), (n, 2)):
        s = PardisoSPD(threads=2, parallel_unknowns=limit)
        s.set_pattern(pat.indptr, pat.indices, pat.block)
        assert s._single.threads == s._double.threads == expected
        s.factor(data)
        solutions[expected] = s.solve(rhs)
    assert np.array_equal(solutions[1], solutions[2])
