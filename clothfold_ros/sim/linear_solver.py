"""Sparse SPD solves for Newton on a persistent pattern: MKL PARDISO phases, SciPy fallback.

The Newton matrix keeps one upper block-triangular pattern of 3x3 vertex blocks across
iterations (BSR, see `pattern.HessianPattern`); only its values change. PARDISO then
runs the symbolic analysis (reordering, phase 11) once per pattern and only the numeric
factorization (phase 22) and the solve (phase 33) per Newton iteration. Given as blocks
(iparm[36] = 3) PARDISO orders the vertex graph instead of the DOF graph: on Newton
matrices of the 12K fold the analysis took 11-13 ms instead of 45-93 ms, the factorization
about as long as entry by entry (bench/bench_linear.py compares both). Indices are zero-based
(iparm[34] = 1) and the matrix type is real SPD (mtype 2), so nothing is copied.

With precision "mixed" (the default) the factorization is computed in single precision
(iparm[27] = 1: half the memory traffic, 1.4-1.7x faster at 12K) and every solve is
refined in double precision against the double matrix (x += L^-T L^-1 (b - A x)) until
the relative residual is below `tolerance` (1e-8: the Newton direction to eight digits,
where the Newton tolerance needs about three; a double factorization gives about 3e-14),
normally in two single-precision solves (one refinement). Where the single factorization
fails or the refinement does not converge, that system is factorized in double precision
(counted in `fallbacks`), so no solve returns an answer outside the tolerance.

PARDISO runs on `threads` MKL threads (a thread-local setting, default 1) for systems of at
least `PARALLEL_UNKNOWNS` unknowns and on one thread below (the 3K fold's systems and the
subspace systems of simulator.py: threading them made the fold slower). With more than
one, MKL's conditional numerical reproducibility mode (MKL_CBWR, set before MKL loads)
and PARDISO's CNR thread count (iparm[33]) keep results bit-for-bit reproducible for a
given thread count; KMP_BLOCKTIME=0 (also set before MKL loads, unless set already) stops
MKL's idle threads from spinning on the cores the rest of the Newton iteration needs.
"""
from __future__ import annotations

import ctypes
import os

import numba as nb
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

os.environ.setdefault("MKL_CBWR", "AUTO")  # reproducible threaded PARDISO; read when MKL loads
# MKL's OpenMP threads sleep right after a parallel region instead of spinning for 200 ms
# on the core the numba kernels, CCD and other processes need between two factorizations
# (3K fold on two threads: 37.5 instead of 57.7 CPU seconds; 12K: 1.03x faster, same run).
os.environ.setdefault("KMP_BLOCKTIME", "0")
try:  # MKL PARDISO through the library handle pypardiso loads (pypardiso finds mkl_rt).
    import pypardiso

    _HAVE_PARDISO = True
except ImportError:  # pragma: no cover - exercised only where MKL is missing
    _HAVE_PARDISO = False

_I32P = ctypes.POINTER(ctypes.c_int32)
_F64P = ctypes.POINTER(ctypes.c_double)
_I64P = ctypes.POINTER(ctypes.c_int64)
_MTYPE_SPD = 2
PRECISIONS = ("double", "mixed")
# Systems smaller than this run PARDISO on one thread: on the 3K fold (4.8K unknowns and the
# smaller subspace systems) two threads made the fold 0.73x as fast, at 12K (18.7K) 1.14x.
PARALLEL_UNKNOWNS = 10_000


@nb.njit(cache=True)
def _upper_matvec(indptr, indices, data, x):
    """A x for symmetric A given by its upper triangle in CSR."""
    y = np.zeros(len(x))
    for a in range(len(indptr) - 1):
        xa, acc = x[a], 0.0
        for s in range(indptr[a], indptr[a + 1]):
            b, v = indices[s], data[s]
            acc += v * x[b]
            if b != a:
                y[b] += v * xa
        y[a] += acc
    return y


@nb.njit(cache=True)
def _upper_block3_matvec(indptr, indices, data, x):
    """A x for symmetric A given by its upper 3x3 block triangle (diagonal blocks whole, row-major)."""
    y = np.zeros(len(x))
    for a in range(len(indptr) - 1):
        xa0, xa1, xa2 = x[3 * a], x[3 * a + 1], x[3 * a + 2]
        y0 = y1 = y2 = 0.0
        for s in range(indptr[a], indptr[a + 1]):
            b, k = indices[s], 9 * s
            xb0, xb1, xb2 = x[3 * b], x[3 * b + 1], x[3 * b + 2]
            m0, m1, m2, m3, m4, m5, m6, m7, m8 = (data[k], data[k + 1], data[k + 2], data[k + 3], data[k + 4],
                                                  data[k + 5], data[k + 6], data[k + 7], data[k + 8])
            y0 += m0 * xb0 + m1 * xb1 + m2 * xb2
            y1 += m3 * xb0 + m4 * xb1 + m5 * xb2
            y2 += m6 * xb0 + m7 * xb1 + m8 * xb2
            if b != a:
                y[3 * b] += m0 * xa0 + m3 * xa1 + m6 * xa2
                y[3 * b + 1] += m1 * xa0 + m4 * xa1 + m7 * xa2
                y[3 * b + 2] += m2 * xa0 + m5 * xa1 + m8 * xa2
        y[3 * a] += y0
        y[3 * a + 1] += y1
        y[3 * a + 2] += y2
    return y


def symmetric_block_matvec(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, block: int,
                           x: np.ndarray) -> np.ndarray:
    """A x for the symmetric A given by its upper block triangle (diagonal blocks whole,
    blocks row-major, the layout of `pattern.HessianPattern`); block 1 is plain upper CSR."""
    if block == 3:
        return _upper_block3_matvec(indptr, indices, data, x)
    if block == 1:
        return _upper_matvec(indptr, indices, data, x)
    raise ValueError(f"block must be 1 or 3, got {block}")


class _Handle:
    """One PARDISO instance (internal memory, parameters, permutation) in one precision."""

    def __init__(self, lib, ordering: int, refinement_steps: int, threads: int, single: bool) -> None:
        self._mkl = lib.libmkl
        self._pardiso = lib._mkl_pardiso  # argtypes already declared by pypardiso
        self.dtype = np.float32 if single else np.float64
        self.pt = np.zeros(64, dtype=np.int64)
        self.iparm = np.zeros(64, dtype=np.int32)
        self._mkl.pardisoinit(self.pt.ctypes.data_as(_I64P), ctypes.byref(ctypes.c_int32(_MTYPE_SPD)),
                              self.iparm.ctypes.data_as(_I32P))
        self.iparm[0] = 1  # use the iparm values below, not the defaults
        self.iparm[1] = ordering
        self.iparm[7] = int(refinement_steps)
        self.iparm[27] = 1 if single else 0  # single-precision factorization (matrix and vectors float32)
        self.iparm[34] = 1  # zero-based indices
        self.iparm[33] = threads if threads > 1 else 0  # CNR: reproducible for this thread count
        self.threads = threads
        self.analysed = False
        self.n = self.block = 0
        self.indptr = self.indices = self.perm = None

    def set_pattern(self, indptr: np.ndarray, indices: np.ndarray, block: int, threads: int | None = None) -> None:
        """A new pattern (analysed at the next factorization), solved on `threads` (None: as set)."""
        self.free()
        if threads is not None:
            self.threads = threads
            self.iparm[33] = threads if threads > 1 else 0  # CNR: reproducible for this thread count
        self.indptr, self.indices, self.block = indptr, indices, block
        self.n = len(indptr) - 1
        self.iparm[36] = block if block > 1 else 0  # BSR with this block size
        self.perm = np.zeros(self.n, dtype=np.int32)

    def call(self, phase: int, data: np.ndarray, rhs: np.ndarray | None = None) -> np.ndarray | None:
        size = self.n * self.block
        b = np.zeros(size, dtype=self.dtype) if rhs is None else np.ascontiguousarray(rhs, dtype=self.dtype)
        if b.shape != (size,):
            raise ValueError(f"right-hand side must have {size} entries, got {b.shape}")
        x = np.zeros(size, dtype=self.dtype)
        err = ctypes.c_int32(0)
        previous = self._mkl.MKL_Set_Num_Threads_Local(self.threads)
        try:  # pointers are passed untyped: float32 arrays go through the double* argtype
            self._pardiso(
                self.pt.ctypes.data_as(_I64P), ctypes.byref(ctypes.c_int32(1)), ctypes.byref(ctypes.c_int32(1)),
                ctypes.byref(ctypes.c_int32(_MTYPE_SPD)), ctypes.byref(ctypes.c_int32(phase)),
                ctypes.byref(ctypes.c_int32(self.n)), data.ctypes.data_as(_F64P),
                self.indptr.ctypes.data_as(_I32P), self.indices.ctypes.data_as(_I32P),
                self.perm.ctypes.data_as(_I32P), ctypes.byref(ctypes.c_int32(1)), self.iparm.ctypes.data_as(_I32P),
                ctypes.byref(ctypes.c_int32(0)), b.ctypes.data_as(_F64P), x.ctypes.data_as(_F64P), ctypes.byref(err),
            )
        finally:
            self._mkl.MKL_Set_Num_Threads_Local(previous)
        if err.value != 0:
            hint = " (matrix not positive definite)" if err.value == -4 else ""
            raise np.linalg.LinAlgError(f"PARDISO phase {phase} failed with error {err.value}{hint}")
        return x if rhs is not None else None

    def factor(self, data: np.ndarray) -> bool:
        """Numeric factorization of data (in this handle's precision); True if it analysed first."""
        analysed = not self.analysed
        if analysed:
            self.iparm[17] = self.iparm[18] = -1  # negative: report factor nonzeros and MFLOP again
            self.call(11, data)
            self.analysed = True
        self.call(22, data)
        return analysed

    def free(self) -> None:
        if self.n and self.analysed:
            self.call(-1, np.zeros(1, dtype=self.dtype))
        self.analysed = False


class PardisoSPD:
    """PARDISO for one SPD system whose pattern changes rarely and whose values change often.

    `set_pattern(indptr, indices, block)` (upper block triangle, sorted, int32; block:
    rows per block, 1 = plain CSR) schedules an analysis; `factor(data)` factorizes the
    values on that pattern (blocks row-major); `solve(rhs)` solves with it.
    """

    ORDERINGS = {"minimum_degree": 0, "metis": 2}  # iparm[1]

    def __init__(self, ordering: str = "minimum_degree", refinement_steps: int = 0, threads: int = 1,
                 precision: str = "mixed", tolerance: float = 1e-8, max_refinements: int = 8,
                 parallel_unknowns: int = PARALLEL_UNKNOWNS) -> None:
        """ordering: fill-reducing ordering (minimum degree fills less than METIS on these cloth
        matrices); refinement_steps: PARDISO's own refinement steps per double solve (0: with
        the diagonal scaling the residual is ~1e-13 without); threads: MKL threads
        (reproducible per count), used for systems of at least `parallel_unknowns` unknowns
        (smaller ones run on one); precision: "mixed" (single factorization, double
        refinement to `tolerance`, relative residual, in at most `max_refinements` steps)
        or "double"."""
        if not _HAVE_PARDISO:
            raise ImportError("pypardiso (MKL) is not installed")
        if ordering not in self.ORDERINGS:
            raise ValueError(f"unknown ordering {ordering!r} ({', '.join(self.ORDERINGS)})")
        if precision not in PRECISIONS:
            raise ValueError(f"unknown precision {precision!r} ({', '.join(PRECISIONS)})")
        if threads < 1:
            raise ValueError(f"threads must be >= 1, got {threads}")
        if not 0.0 < tolerance < 1.0 or max_refinements < 1:
            raise ValueError("tolerance must be in (0, 1) and max_refinements >= 1")
        self._lib = pypardiso.PyPardisoSolver(mtype=_MTYPE_SPD)  # owns the mkl_rt handle
        self.threads = int(threads)
        self.parallel_unknowns = int(parallel_unknowns)
        self.precision = precision
        self.tolerance = float(tolerance)
        self.max_refinements = int(max_refinements)
        order = self.ORDERINGS[ordering]
        self._double = _Handle(self._lib, order, refinement_steps, self.threads, single=False)
        self._single = _Handle(self._lib, order, 0, self.threads, single=True) if precision == "mixed" else None
        self._indptr = self._indices = None
        self._block = 1
        self._data = self._data32 = None
        self._use_single = False  # the current values are factorized in single precision
        self.analyses = 0  # symbolic analyses run (for statistics)
        self.fallbacks = 0  # systems factorized in double precision because mixed precision failed
        self.refinements = 0  # single-precision refinement solves (for statistics)

    def set_pattern(self, indptr: np.ndarray, indices: np.ndarray, block: int = 1) -> None:
        if block < 1:
            raise ValueError(f"block must be >= 1, got {block}")
        self._indptr = np.ascontiguousarray(indptr, dtype=np.int32)
        self._indices = np.ascontiguousarray(indices, dtype=np.int32)
        self._block = int(block)
        unknowns = (len(self._indptr) - 1) * self._block
        threads = self.threads if unknowns >= self.parallel_unknowns else 1
        for h in (self._double, self._single):
            if h is not None:
                h.set_pattern(self._indptr, self._indices, self._block, threads)

    def factor(self, data: np.ndarray) -> None:
        self._data = np.ascontiguousarray(data, dtype=float)
        self._use_single = False
        if self._single is not None:
            try:
                self._data32 = self._data.astype(np.float32)
                self.analyses += self._single.factor(self._data32)
                self._use_single = True
                return
            except np.linalg.LinAlgError:  # not SPD in single precision: this system in double
                self.fallbacks += 1
        self._factor_double()

    def _factor_double(self) -> None:
        self.analyses += self._double.factor(self._data)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        if not self._use_single:
            return self._double.call(33, self._data, rhs)
        b = np.ascontiguousarray(rhs, dtype=float)
        x = self._single.call(33, self._data32, b).astype(float)  # validates the size
        bound = self.tolerance * float(np.linalg.norm(b))
        for _ in range(self.max_refinements):
            r = b - symmetric_block_matvec(self._indptr, self._indices, self._data, self._block, x)
            if float(np.linalg.norm(r)) <= bound:
                return x
            x += self._single.call(33, self._data32, r)
            self.refinements += 1
        r = b - symmetric_block_matvec(self._indptr, self._indices, self._data, self._block, x)
        if float(np.linalg.norm(r)) <= bound:
            return x
        self.fallbacks += 1  # refinement too slow (ill-conditioned): this system in double
        self._use_single = False
        self._factor_double()
        return self._double.call(33, self._data, b)

    @property
    def factor_nonzeros(self) -> int:
        """Nonzeros of the Cholesky factor (PARDISO's report after the analysis; counted in
        blocks for a block pattern)."""
        return int((self._single or self._double).iparm[17])

    @property
    def factor_mflop(self) -> int:
        """MFLOP of one numeric factorization (PARDISO's report after the analysis; in block
        operations for a block pattern, so not comparable with a plain CSR pattern's)."""
        return int((self._single or self._double).iparm[18])

    def free(self) -> None:
        for h in (self._double, self._single):
            if h is not None:
                h.free()

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
        self.fallbacks = 0  # interface parity with PardisoSPD (SuperLU factorizes in double)

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


def spd_solver(backend: str = "auto", threads: int = 1, precision: str = "mixed") -> PardisoSPD | ScipySPD:
    """The fastest SPD solver available ("auto"), or "pardiso" / "superlu" by name; precision
    "mixed" or "double" applies to PARDISO (SuperLU always factorizes in double)."""
    if backend == "auto":
        backend = "pardiso" if _HAVE_PARDISO else "superlu"
    if backend == "pardiso":
        return PardisoSPD(threads=threads, precision=precision)
    if backend == "superlu":
        return ScipySPD()
    raise ValueError(f"unknown linear solver {backend!r} (pardiso, superlu, auto)")
