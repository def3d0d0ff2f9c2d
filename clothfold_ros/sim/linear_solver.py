"""Sparse symmetric positive-definite solves for Newton: MKL Pardiso, SciPy fallback."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

try:  # MKL Pardiso (pypardiso) in SPD mode on the upper triangle: the fastest here.
    import pypardiso

    _HAVE_PARDISO = True
except ImportError:  # pragma: no cover - exercised only where MKL is missing
    _HAVE_PARDISO = False


class SPDSolver:
    """Solve H p = r with H symmetric positive definite, given its upper triangle (CSR)."""

    def __init__(self, backend: str = "auto") -> None:
        if backend == "auto":
            backend = "pardiso" if _HAVE_PARDISO else "superlu"
        if backend == "pardiso" and not _HAVE_PARDISO:
            raise ValueError("pypardiso is not installed; use backend='superlu'")
        self.backend = backend
        if backend == "pardiso":
            self._pardiso = pypardiso.PyPardisoSolver(mtype=2)
            self._n = -1

    def solve(self, upper: sp.csr_matrix, rhs: np.ndarray) -> np.ndarray:
        if self.backend == "pardiso":
            a = sp.csr_matrix(upper)
            a.sort_indices()
            if a.shape[0] != self._n:  # new system size: drop the old factorization
                self._pardiso.free_memory(everything=True)
                self._n = a.shape[0]
            # One MKL thread for this call: a threaded factorization sums in a run-dependent
            # order, which made folds of ~3K triangles differ from run to run (the simulator
            # promises bit-for-bit determinism). Thread-local, so nothing else is affected.
            previous = self._pardiso.libmkl.MKL_Set_Num_Threads_Local(1)
            try:
                x = self._pardiso.solve(a, rhs)
            except pypardiso.pardiso_wrapper.PyPardisoError as err:
                raise np.linalg.LinAlgError(f"Pardiso failed: {err}") from err
            finally:
                self._pardiso.libmkl.MKL_Set_Num_Threads_Local(previous)
            return np.asarray(x).ravel()
        full = upper + sp.triu(upper, k=1).T
        return spla.spsolve(full.tocsc(), rhs)
