"""Fixed-pattern sparse assembly of per-element gradients and Hessians.

The elastic sparsity pattern never changes, so the map from element-local entries to
the CSR data array is computed once; each assembly is then one `np.bincount`.
Only the upper triangle is kept (the solver takes a symmetric upper triangle).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def element_dofs(elements: np.ndarray) -> np.ndarray:
    """(E, 3k) DOF indices of elements given as (E, k) vertex ids (vertex-major xyz)."""
    e = np.asarray(elements, dtype=np.int64)
    return (3 * e[:, :, None] + np.arange(3)).reshape(len(e), -1)


class UpperPattern:
    """Upper-triangular CSR pattern for a list of element DOF blocks plus the diagonal."""

    def __init__(self, ndof: int, blocks: list[np.ndarray]) -> None:
        rows, cols, self._slices = [], [], []
        offset = 0
        for dofs in blocks:
            k = dofs.shape[1]
            r = np.repeat(dofs, k, axis=1).ravel()
            c = np.tile(dofs, (1, k)).ravel()
            rows.append(r)
            cols.append(c)
            self._slices.append((offset, offset + r.size, dofs.shape[0], k))
            offset += r.size
        rows.append(np.arange(ndof))
        cols.append(np.arange(ndof))
        r = np.concatenate(rows)
        c = np.concatenate(cols)
        upper = r <= c
        key = np.where(upper, r * ndof + c, c * ndof + r)  # fold lower entries onto upper
        uniq, inverse = np.unique(key, return_inverse=True)
        self.ndof = ndof
        self.n_entries = offset
        self._target = inverse
        self._keep = np.ones(r.size, dtype=bool)
        # Lower entries of element blocks are dropped (their mirror is counted once).
        self._keep[: offset] = upper[: offset] | (r[: offset] == c[: offset])
        self.nnz = uniq.size
        self.indices = (uniq % ndof).astype(np.int32)
        row_of = uniq // ndof
        self.indptr = np.searchsorted(row_of, np.arange(ndof + 1)).astype(np.int32)
        self._target_kept = self._target[self._keep]

    def assemble(self, hessians: list[np.ndarray], diagonal: np.ndarray) -> sp.csr_matrix:
        """CSR upper triangle of sum of element Hessians (in block order) + diag(diagonal)."""
        vals = np.concatenate([h.reshape(-1) for h in hessians] + [diagonal])
        data = np.bincount(self._target_kept, weights=vals[self._keep], minlength=self.nnz)
        return sp.csr_matrix((data, self.indices, self.indptr), shape=(self.ndof, self.ndof))


def scatter_gradient(ndof: int, dofs: np.ndarray, grads: np.ndarray) -> np.ndarray:
    """Sum per-element gradients (E, 3k) into a global vector of length ndof."""
    return np.bincount(dofs.ravel(), weights=grads.ravel(), minlength=ndof)
