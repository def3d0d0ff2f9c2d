"""Solver settings of the IPC cloth simulator (docs/method.md section 3)."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class SimConfig:
    """Time stepping, Newton and contact settings. SI units.

    The contact offset xi and the barrier activation distance dhat default to the cloth
    thickness (None = use the material's thickness).
    """

    dt: float = 0.04  # s, implicit Euler time step
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)  # m/s^2, table frame
    newton_tol: float = 1e-3  # m/s: stop when RMS(|dx|)/dt <= tol ...
    newton_window: int = 1  # ... over this many last iterations
    max_newton_iterations: int = 400  # a cap that is hit is a failure to investigate, not a result
    max_line_search_halvings: int = 30
    model_ratio: float = 0.1  # a step gaining less than this share of the model's decrease tries shorter ones (0: off)
    grasp_stiffness: float = 6e7  # N/m per kg of held cloth (1/s^2): spring from cloth to grip point
    grasp_slip: float = 2e-3  # m: held cloth farther than this from its grip point slips in the grip
    psd_projection: str = "clamp"  # "clamp" or "abs": negative membrane eigenvalues set to 0 or |.|
    pattern_growth_rings: int = 0  # a new contact pair also adds its neighbours' pairs (rings) to the pattern
    pattern_keep_solves: int = 1  # contact entries unused for this many steps are stale ...
    pattern_prune_fraction: float = 0.0  # ... and dropped once they are this share of the contact entries
    pattern_growth_iterations: int = 3  # new contact pairs join the pattern in a solve's first N iterations, later ones wait
    linear_solver: str = "auto"  # "pardiso", "superlu" or "auto" (PARDISO when MKL is there)
    linear_precision: str = "mixed"  # PARDISO: "mixed" (single factorization, double refinement to 1e-8) or "double"
    xi: float | None = None  # m, minimum mid-surface separation (offset)
    dhat: float | None = None  # m, barrier activation distance beyond xi
    ccd_fraction: float = 0.99  # CCD keeps pairs this fraction of xi apart; the line search enforces xi
    eps_v: float = 1e-3  # m/s, smoothed static friction velocity
    broad_phase_reuse: float = 5e-4  # m: contact candidates are reused while no vertex moved farther
    table_margin: float = 0.05  # m the table extends beyond the cloth's rest footprint
    regularization_shifts: tuple[float, ...] = (1e-12, 1e-10, 1e-8, 1e-6)  # x diag: retries of a failed factorization
    subspace_threshold: float = 1e-4  # m/s: after subspace_start full Newton iterations of a step, solve only for
    #   the vertices whose last full step exceeded this speed (and their neighbours); 0: always all vertices
    subspace_start: int = 2  # full Newton iterations of a step before subspace ones
    subspace_rings: int = 1  # rings of pattern neighbours added to the moving vertices
    subspace_max_share: float = 0.6  # a subspace holding more than this share of the vertices is solved whole
    check_intersections: bool = True  # assert intersection-free after every step
    threads: int = 1  # ipctk threads (1 keeps results bit-for-bit deterministic)
    ccd_threads: int = 1  # ipctk threads of the CCD step-size query (a minimum over pairs: reproducible with any count)
    solver_threads: int = 1  # PARDISO threads (bit-for-bit reproducible with any count: MKL's CNR mode)

    def __post_init__(self) -> None:
        if not self.dt > 0:
            raise ValueError(f"dt must be > 0 s, got {self.dt}")
        if not self.newton_tol > 0:
            raise ValueError(f"newton_tol must be > 0 m/s, got {self.newton_tol}")
        if self.linear_precision not in ("mixed", "double"):
            raise ValueError(f"linear_precision must be 'mixed' or 'double', got {self.linear_precision!r}")
        if self.pattern_growth_iterations < 1:
            raise ValueError("pattern_growth_iterations must be >= 1")
        if self.threads < 1 or self.ccd_threads < 1 or self.solver_threads < 1:
            raise ValueError("threads, ccd_threads and solver_threads must be >= 1")
        shifts = self.regularization_shifts
        if any(not a < b for a, b in zip((0.0, *shifts), shifts)):
            raise ValueError(f"regularization_shifts must be positive and increasing, got {shifts}")
        if self.subspace_threshold < 0 or self.subspace_start < 1 or self.subspace_rings < 0:
            raise ValueError("subspace_threshold must be >= 0 m/s, subspace_start >= 1 and subspace_rings >= 0")
        if not 0.0 < self.subspace_max_share <= 1.0:
            raise ValueError(f"subspace_max_share must be in (0, 1], got {self.subspace_max_share}")
        if self.max_newton_iterations < 1 or self.newton_window < 1:
            raise ValueError("max_newton_iterations and newton_window must be >= 1")
