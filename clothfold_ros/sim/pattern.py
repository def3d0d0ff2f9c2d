"""Persistent upper-triangular CSR pattern of the Newton matrix, grown only when needed.

The pattern holds the elastic blocks (triangles, hinges), the diagonal and the contact
entries seen recently; a contact pair that separates keeps its slot (with zeros), so
the linear solver re-runs its symbolic analysis only when a new pair appears. Entries
that stayed unused for `keep_solves` Newton solves are dropped once they make up a
`prune_fraction` of the contact entries: cloth sliding over cloth meets new pairs all the
time, and a pattern that only grows fills the factorization with dead couplings. A new
pair (a, b) also brings in the pairs of the mesh neighbours of a and b (`growth_rings`
rings around each): contact fronts advance to neighbouring vertices, and each analysis
costs more than the factorizations it saves. Element
Hessians go straight into the CSR value array through precomputed slot maps (one
serial pass, so sums happen in a fixed order: assembly is bit-for-bit reproducible).
"""
from __future__ import annotations

import numba as nb
import numpy as np
import scipy.sparse as sp


def element_dofs(elements: np.ndarray) -> np.ndarray:
    """(E, 3k) DOF indices of elements given as (E, k) vertex ids (vertex-major xyz)."""
    e = np.asarray(elements, dtype=np.int64)
    return (3 * e[:, :, None] + np.arange(3)).reshape(len(e), -1)


def scatter_gradient(ndof: int, dofs: np.ndarray, grads: np.ndarray) -> np.ndarray:
    """Sum per-element gradients (E, 3k) into a global vector of length ndof."""
    return np.bincount(dofs.ravel(), weights=grads.ravel(), minlength=ndof)


def _block_keys(dofs: np.ndarray, ndof: int) -> tuple[np.ndarray, np.ndarray]:
    """Keys r * ndof + c of the upper entries of each element block, and the mask of kept entries."""
    r = np.repeat(dofs, dofs.shape[1], axis=1)
    c = np.tile(dofs, (1, dofs.shape[1]))
    keep = r <= c
    return (r * ndof + c), keep


@nb.njit(cache=True)
def _scatter_blocks(data, slots, blocks, scale):
    """data[slots[e, i]] += scale * blocks[e].ravel()[i] for slots >= 0, in element order."""
    n, k = slots.shape
    for e in range(n):
        flat = blocks[e].ravel()
        for i in range(k):
            s = slots[e, i]
            if s >= 0:
                data[s] += scale * flat[i]


@nb.njit(cache=True)
def _scatter(data, slots, values):
    for i in range(slots.shape[0]):
        data[slots[i]] += values[i]


class HessianPattern:
    """Upper CSR pattern over `ndof` DOFs for element blocks, the diagonal and contacts."""

    def __init__(self, ndof: int, blocks: list[np.ndarray], triangles: np.ndarray | None = None,
                 growth_rings: int = 1, keep_solves: int = 5, prune_fraction: float = 0.25) -> None:
        self.ndof = ndof
        self.keep_solves = keep_solves
        self.prune_fraction = prune_fraction
        self.solves = 0  # begin_solve() calls so far
        self.pending = np.zeros(0, dtype=np.int64)  # contact entries deferred by contact_slots(grow=False)
        self._rings = None
        if triangles is not None and growth_rings > 0:
            nv = ndof // 3
            t = np.asarray(triangles, dtype=np.int64)
            r = np.concatenate([t[:, [0, 1, 2, 0, 1, 2]].ravel(), np.arange(nv)])
            c = np.concatenate([t[:, [1, 2, 0, 2, 0, 1]].ravel(), np.arange(nv)])
            ring = sp.csr_matrix((np.ones(len(r)), (r, c)), shape=(nv, nv))
            ring.data[:] = 1.0
            reach = ring
            for _ in range(growth_rings - 1):
                reach = reach @ ring
            reach.data[:] = 1.0
            self._rings = reach.tocsr()
        self._blocks = [np.asarray(b, dtype=np.int64) for b in blocks]
        keys = [np.arange(ndof, dtype=np.int64) * (ndof + 1)]  # diagonal
        for dofs in self._blocks:
            k, keep = _block_keys(dofs, ndof)
            keys.append(k[keep])
        self._rebuild(np.unique(np.concatenate(keys)))
        self.base_nnz = self.nnz
        self.is_base = np.ones(self.nnz, dtype=bool)  # element or diagonal entry (never pruned)
        self.last_used = np.zeros(self.nnz, dtype=np.int64)  # solve in which a contact entry was last used

    def _rebuild(self, keys: np.ndarray) -> None:
        self._set_keys(keys)
        self.diag_slots = np.searchsorted(keys, np.arange(self.ndof, dtype=np.int64) * (self.ndof + 1))
        self.block_slots = []
        for dofs in self._blocks:
            k, keep = _block_keys(dofs, self.ndof)
            slots = np.searchsorted(keys, k).astype(np.int64)
            slots[~keep] = -1  # lower entries: their mirror is the upper one
            self.block_slots.append(slots)
        self.version = 0

    def _set_keys(self, keys: np.ndarray) -> None:
        """The sorted keys r * ndof + c and the CSR arrays (rows, indices, indptr) they define."""
        self.keys = keys
        self.nnz = len(keys)
        self.rows = (keys // self.ndof).astype(np.int32)
        self.indices = (keys % self.ndof).astype(np.int32)
        self.indptr = np.searchsorted(self.rows, np.arange(self.ndof + 1)).astype(np.int32)

    def _insert(self, new_keys: np.ndarray) -> None:
        """Add sorted keys absent from the pattern; existing slots shift past the inserted ones."""
        shift = np.searchsorted(new_keys, self.keys)  # inserted keys below each old key
        old_to_new = np.arange(self.nnz) + shift
        where = np.searchsorted(self.keys, new_keys)
        self.is_base = np.insert(self.is_base, where, False)
        self.last_used = np.insert(self.last_used, where, self.solves)
        self._set_keys(np.insert(self.keys, where, new_keys))
        self._remap(old_to_new)

    def _remap(self, old_to_new: np.ndarray) -> None:
        self.diag_slots = old_to_new[self.diag_slots]
        for i, slots in enumerate(self.block_slots):
            self.block_slots[i] = np.where(slots >= 0, old_to_new[slots], -1)
        self.version += 1

    def _prune(self) -> bool:
        """Drop contact entries unused for more than keep_solves solves, if they are many."""
        stale = ~self.is_base & (self.last_used < self.solves - self.keep_solves)
        n_stale = int(stale.sum())
        if n_stale == 0 or n_stale < self.prune_fraction * (self.nnz - self.base_nnz):
            return False
        keep = ~stale
        old_to_new = np.cumsum(keep) - 1
        self.is_base, self.last_used = self.is_base[keep], self.last_used[keep]
        self._set_keys(self.keys[keep])
        self._remap(old_to_new)
        return True

    def begin_solve(self) -> bool:
        """Start a Newton solve: prune stale contact entries, add the deferred ones; True if
        the pattern changed (the solver then re-runs its analysis)."""
        self.solves += 1
        pruned = self._prune()
        return self.grow_pending() or pruned

    def contact_slots(self, hessian: sp.spmatrix, grow: bool = True) -> tuple[np.ndarray, np.ndarray, bool]:
        """Slots and values of the upper entries of a symmetric sparse contact Hessian.

        grow: entries the pattern lacks are added (the third value says it grew). Otherwise
        the pattern stays: each missing off-diagonal vertex block B (between vertices i, j)
        is dropped and ||B||_F is added to the diagonal of both vertices instead. That
        matrix is the Hessian plus a PSD term (the eigenvalues of [[0, B], [B^T, 0]] are
        +-sigma(B) <= ||B||_F), so it stays SPD and Newton keeps a descent direction; the
        missing entries wait in `pending` until `grow_pending`.
        """
        coo = hessian.tocoo()
        upper = coo.row <= coo.col
        keys = coo.row[upper].astype(np.int64) * self.ndof + coo.col[upper]
        vals = coo.data[upper]
        slots = np.searchsorted(self.keys, keys)
        slots_c = np.minimum(slots, self.nnz - 1)
        missing = self.keys[slots_c] != keys
        if not missing.any():
            self.last_used[slots] = self.solves
            return slots, vals, False
        if grow:
            self._insert(self._with_neighbours(np.unique(keys[missing])))
            slots = np.searchsorted(self.keys, keys)
            self.last_used[slots] = self.solves
            return slots, vals, True
        self.last_used[slots[~missing]] = self.solves
        miss_keys, miss_vals = keys[missing], vals[missing]
        self.pending = np.union1d(self.pending, miss_keys)
        rows, cols = miss_keys // self.ndof, miss_keys % self.ndof
        pair = (rows // 3) * (self.ndof // 3) + cols // 3
        uniq, inv = np.unique(pair, return_inverse=True)
        norm = np.sqrt(np.bincount(inv, weights=miss_vals**2))
        nv = self.ndof // 3
        bump = np.bincount(np.concatenate([uniq // nv, uniq % nv]), weights=np.concatenate([norm, norm]),
                           minlength=nv)
        keep = ~missing
        diag = np.repeat(bump, 3)
        return (np.concatenate([slots[keep], self.diag_slots]), np.concatenate([vals[keep], diag]), False)

    def grow_pending(self) -> bool:
        """Add the entries deferred by contact_slots(grow=False); True if the pattern grew."""
        if not len(self.pending):
            return False
        new = self._with_neighbours(self.pending)
        self.pending = np.zeros(0, dtype=np.int64)
        if not len(new):
            return False
        self._insert(new)
        return True

    def _with_neighbours(self, new: np.ndarray) -> np.ndarray:
        """Keys absent from the pattern among `new` and, with growth rings, their neighbours' pairs."""
        if self._rings is not None:
            new = np.union1d(new, self._neighbour_keys(new))
        present = self.keys[np.minimum(np.searchsorted(self.keys, new), self.nnz - 1)] == new
        return new[~present]

    def _neighbour_keys(self, keys: np.ndarray) -> np.ndarray:
        """Upper DOF keys of every vertex pair (a', b'), a' near a, b' near b, for the pairs in keys."""
        nv = self.ndof // 3
        va, vb = (keys // self.ndof) // 3, (keys % self.ndof) // 3
        pairs = sp.csr_matrix((np.ones(len(va)), (va, vb)), shape=(nv, nv))
        grown = (self._rings @ pairs @ self._rings.T).tocoo()
        a = np.minimum(grown.row, grown.col).astype(np.int64)
        b = np.maximum(grown.row, grown.col).astype(np.int64)
        r = (3 * a[:, None] + np.arange(3))[:, :, None]
        c = (3 * b[:, None] + np.arange(3))[:, None, :]
        r, c = np.broadcast_arrays(r, c)
        r, c = r.ravel(), c.ravel()
        upper = r <= c
        return np.unique(r[upper] * self.ndof + c[upper])

    def assemble(self, element_hessians: list[np.ndarray], scale: float, diagonal: np.ndarray,
                 contact: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """CSR values of scale * sum(element Hessians) + diag(diagonal) (+ contact entries)."""
        data = np.zeros(self.nnz)
        for slots, blocks in zip(self.block_slots, element_hessians):
            _scatter_blocks(data, slots, blocks, scale)
        data[self.diag_slots] += diagonal
        if contact is not None:
            _scatter(data, contact[0], contact[1])
        return data

    def matrix(self, data: np.ndarray) -> sp.csr_matrix:
        """The upper triangle as a SciPy CSR matrix (for tests and inspection)."""
        return sp.csr_matrix((data, self.indices, self.indptr), shape=(self.ndof, self.ndof))
