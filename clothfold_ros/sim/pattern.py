"""Persistent upper-triangular CSR pattern of the Newton matrix, grown only when needed.

The pattern holds the elastic blocks (triangles, hinges), the diagonal and every
contact entry seen so far; a contact pair that separates keeps its slot (with zeros), so
the linear solver re-runs its symbolic analysis only when a new pair appears. Element
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

    def __init__(self, ndof: int, blocks: list[np.ndarray]) -> None:
        self.ndof = ndof
        self._blocks = [np.asarray(b, dtype=np.int64) for b in blocks]
        keys = [np.arange(ndof, dtype=np.int64) * (ndof + 1)]  # diagonal
        for dofs in self._blocks:
            k, keep = _block_keys(dofs, ndof)
            keys.append(k[keep])
        self._rebuild(np.unique(np.concatenate(keys)))

    def _rebuild(self, keys: np.ndarray) -> None:
        self.keys = keys
        self.nnz = len(keys)
        rows = keys // self.ndof
        self.indices = (keys % self.ndof).astype(np.int32)
        self.indptr = np.searchsorted(rows, np.arange(self.ndof + 1)).astype(np.int32)
        self.diag_slots = np.searchsorted(keys, np.arange(self.ndof, dtype=np.int64) * (self.ndof + 1))
        self.block_slots = []
        for dofs in self._blocks:
            k, keep = _block_keys(dofs, self.ndof)
            slots = np.searchsorted(keys, k).astype(np.int64)
            slots[~keep] = -1  # lower entries: their mirror is the upper one
            self.block_slots.append(slots)
        self.version = 0

    def _insert(self, new_keys: np.ndarray) -> None:
        """Add sorted keys absent from the pattern; existing slots shift past the inserted ones."""
        shift = np.searchsorted(new_keys, self.keys)  # inserted keys below each old key
        old_to_new = np.arange(self.nnz) + shift
        self.keys = np.insert(self.keys, np.searchsorted(self.keys, new_keys), new_keys)
        self.nnz = len(self.keys)
        rows = self.keys // self.ndof
        self.indices = (self.keys % self.ndof).astype(np.int32)
        self.indptr = np.searchsorted(rows, np.arange(self.ndof + 1)).astype(np.int32)
        self.diag_slots = old_to_new[self.diag_slots]
        for i, slots in enumerate(self.block_slots):
            self.block_slots[i] = np.where(slots >= 0, old_to_new[slots], -1)
        self.version += 1

    def contact_slots(self, hessian: sp.spmatrix) -> tuple[np.ndarray, np.ndarray, bool]:
        """Slots and values of the upper entries of a symmetric sparse contact Hessian.

        Grows the pattern by entries it lacks; the third value says whether it grew.
        """
        coo = hessian.tocoo()
        upper = coo.row <= coo.col
        keys = coo.row[upper].astype(np.int64) * self.ndof + coo.col[upper]
        vals = coo.data[upper]
        slots = np.searchsorted(self.keys, keys)
        slots_c = np.minimum(slots, self.nnz - 1)
        missing = self.keys[slots_c] != keys
        grew = bool(missing.any())
        if grew:
            self._insert(np.unique(keys[missing]))
            slots = np.searchsorted(self.keys, keys)
        return slots, vals, grew

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
