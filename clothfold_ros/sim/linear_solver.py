"""Sparse SPD solves for Newton on a persistent pattern: MKL PARDISO phases, SciPy fallback.

The Newton matrix keeps one upper block-triangular pattern of 3x3 vertex blocks across
iterations (BSR, see `pattern.HessianPattern`); only its values change. PARDISO then
runs the symbolic analysis (reordering, phase 11) once per pattern and only the numeric
factorization (phase 22) and the solve (phase 33) per Newton iteration. Given as blocks
(iparm[36] = 3) PARDISO orders the vertex graph instead of the DOF graph: on Newton
matrices of the 12K fold the analysis took 11-13 ms instead of 45-93 ms, the factorization
about as long as entry by entry (bench/bench_linear.py compares both). Indices are zero-based
(iparm[34] = 1) and the matrix type is real SPD (mtype 2), so nothing is copied.

PARDISO runs on `threads` MKL threads (a thread-local setting, default 1). With more than
one, MKL's conditional numerical reproducibility mode (MKL_CBWR, set before MKL loads)
and PARDISO's CNR thread count (iparm[33]) keep results bit-for-bit reproducible for a
given thread count.
"""
from __future__ import annotations

import ctypes
import os

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

os.environ.setdefault("MKL_CBWR", "AUTO")  # reproducible threaded PARDISO; read when MKL loads
try:  # MKL PARDISO through the library handle pypardiso loads (pypardiso finds mkl_rt).
    import pypardiso

    _HAVE_PARDISO = True
except ImportError:  # pragma: no cover - exercised only where MKL is missing
    _HAVE_PARDISO = False

_I32P = ctypes.POINTER(ctypes.c_int32)
_F64P = ctypes.POINTER(ctypes.c_double)
_MTYPE_SPD = 2


class PardisoSPD:
    """PARDISO for one SPD system whose pattern changes rarely and whose values change often.

    `set_pattern(indptr, indices, block)` (upper block triangle, sorted, int32; block:
    rows per block, 1 = plain CSR) schedules an analysis; `factor(data)` factorizes the
    values on that pattern (blocks row-major); `solve(rhs)` solves with it.
    """

    ORDERINGS = {"minimum_degree": 0, "metis": 2}  # iparm[1]

    def __init__(self, ordering: str = "minimum_degree", refinement_steps: int = 0, threads: int = 1) -> None:
        """ordering: fill-reducing ordering (minimum degree fills less than METIS on these cloth
        matrices); refinement_steps: iterative refinement steps per solve (0: with the diagonal
        scaling the residual is ~1e-13 without); threads: MKL threads (reproducible per count)."""
        if not _HAVE_PARDISO:
            raise ImportError("pypardiso (MKL) is not installed")
        if ordering not in self.ORDERINGS:
            raise ValueError(f"unknown ordering {ordering!r} ({', '.join(self.ORDERINGS)})")
        self._lib = pypardiso.PyPardisoSolver(mtype=_MTYPE_SPD)  # owns the mkl_rt handle
        self._mkl = self._lib.libmkl
        self._pardiso = self._lib._mkl_pardiso  # argtypes already declared by pypardiso
        self._pt = np.zeros(64, dtype=np.int64)
        self._iparm = np.zeros(64, dtype=np.int32)
        self._mkl.pardisoinit(self._pt.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)),
                              ctypes.byref(ctypes.c_int32(_MTYPE_SPD)), self._iparm.ctypes.data_as(_I32P))
        self._iparm[0] = 1  # use the iparm values below, not the defaults
        self._iparm[1] = self.ORDERINGS[ordering]
        self._iparm[7] = int(refinement_steps)
        self._iparm[34] = 1  # zero-based indices
        if threads < 1:
            raise ValueError(f"threads must be >= 1, got {threads}")
        self.threads = int(threads)
        self._iparm[33] = self.threads if self.threads > 1 else 0  # CNR: reproducible for this thread count
        self._perm = np.zeros(0, dtype=np.int32)
        self._n = 0  # block rows
        self._block = 1
        self._indptr = self._indices = None
        self._data = None
        self._analysed = False
        self.analyses = 0  # symbolic analyses run (for statistics)

    def set_pattern(self, indptr: np.ndarray, indices: np.ndarray, block: int = 1) -> None:
        if block < 1:
            raise ValueError(f"block must be >= 1, got {block}")
        self.free()
        self._indptr = np.ascontiguousarray(indptr, dtype=np.int32)
        self._indices = np.ascontiguousarray(indices, dtype=np.int32)
        self._n = len(self._indptr) - 1
        self._block = int(block)
        self._iparm[36] = self._block if self._block > 1 else 0  # BSR with this block size
        self._perm = np.zeros(self._n, dtype=np.int32)
        self._analysed = False

    def _call(self, phase: int, data: np.ndarray, rhs: np.ndarray | None = None) -> np.ndarray | None:
        size = self._n * self._block
        b = np.zeros(size) if rhs is None else np.ascontiguousarray(rhs, dtype=float)
        if b.shape != (size,):
            raise ValueError(f"right-hand side must have {size} entries, got {b.shape}")
        x = np.zeros(size)
        err = ctypes.c_int32(0)
        previous = self._mkl.MKL_Set_Num_Threads_Local(self.threads)
        try:
            self._pardiso(
                self._pt.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)), ctypes.byref(ctypes.c_int32(1)),
                ctypes.byref(ctypes.c_int32(1)), ctypes.byref(ctypes.c_int32(_MTYPE_SPD)),
                ctypes.byref(ctypes.c_int32(phase)), ctypes.byref(ctypes.c_int32(self._n)),
                data.ctypes.data_as(_F64P), self._indptr.ctypes.data_as(_I32P), self._indices.ctypes.data_as(_I32P),
                self._perm.ctypes.data_as(_I32P), ctypes.byref(ctypes.c_int32(1)), self._iparm.ctypes.data_as(_I32P),
                ctypes.byref(ctypes.c_int32(0)), b.ctypes.data_as(_F64P), x.ctypes.data_as(_F64P), ctypes.byref(err),
            )
        finally:
            self._mkl.MKL_Set_Num_Threads_Local(previous)
        if err.value != 0:
            hint = " (matrix not positive definite)" if err.value == -4 else ""
            raise np.linalg.LinAlgError(f"PARDISO phase {phase} failed with error {err.value}{hint}")
        return x if rhs is not None else None

    def factor(self, data: np.ndarray) -> None:
        self._data = np.ascontiguousarray(data, dtype=float)
        if not self._analysed:
            self._iparm[17] = self._iparm[18] = -1  # negative: report factor nonzeros and MFLOP again
            self._call(11, self._data)
            self._analysed = True
            self.analyses += 1
        self._call(22, self._data)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self._call(33, self._data, rhs)

    @property
    def factor_nonzeros(self) -> int:
        """Nonzeros of the Cholesky factor (PARDISO's report after the analysis; counted in
        blocks for a block pattern)."""
        return int(self._iparm[17])

    @property
    def factor_mflop(self) -> int:
        """MFLOP of one numeric factorization (PARDISO's report after the analysis; in block
        operations for a block pattern, so not comparable with a plain CSR pattern's)."""
        return int(self._iparm[18])

    def free(self) -> None:
        if self._n and self._analysed:
            self._call(-1, np.zeros(1))
        self._analysed = False

    def __del__(self) -> None:  # release PARDISO's internal memory
        try:
            self.free()
        except Exception:  # noqa: BLE001 - interpreter shutdown
            pass


class ScipySPD:
    """Fallback with the same interface: SuperLU on the full symmetric matrix (slow)."""

    def __init__(self) -> None:
        self._indptr = self._indices = None
        self._lu = None
        self.analyses = 0

    def set_pattern(self, indptr: np.ndarray, indices: np.ndarray, block: int = 1) -> None:
        self._indptr, self._indices, self._block = indptr, indices, int(block)

    def factor(self, data: np.ndarray) -> None:
        b = self._block
        n = (len(self._indptr) - 1) * b
        blocks = sp.bsr_matrix((np.asarray(data).reshape(-1, b, b), self._indices, self._indptr), shape=(n, n))
        upper = sp.triu(blocks.tocsr())
        full = (upper + sp.triu(upper, k=1).T).tocsc()
        self._lu = spla.splu(full)
        self.analyses += 1

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self._lu.solve(np.asarray(rhs, dtype=float))


def spd_solver(backend: str = "auto", threads: int = 1) -> PardisoSPD | ScipySPD:
    """The fastest SPD solver available ("auto"), or "pardiso" / "superlu" by name."""
    if backend == "auto":
        backend = "pardiso" if _HAVE_PARDISO else "superlu"
    if backend == "pardiso":
        return PardisoSPD(threads=threads)
    if backend == "superlu":
        return ScipySPD()
    raise ValueError(f"unknown linear solver {backend!r} (pardiso, superlu, auto)")
