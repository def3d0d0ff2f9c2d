"""Solver settings of the IPC cloth simulator (docs/method.md section 3)."""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SimConfig:
    """Time stepping, Newton and contact settings. SI units.

    The contact offset xi and the barrier activation distance dhat default to the cloth
    thickness (None = use the material's thickness).
    """

    dt: float = 0.04  # s, implicit Euler time step
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)  # m/s^2, table frame
    newton_tol: float = 1e-3  # m/s: stop when RMS(|dx|)/dt <= tol ...
    newton_window: int = 1  # ... over this many last iterations ...
    force_tol: float | None = None  # m/s: optionally also require the free vertices' unbalanced force, as the
    #   velocity it would add in one step (RMS of h |g_i| / m_i), below this; None: off (3x the cost at 12K)
    max_newton_iterations: int = 400  # a cap that is hit is a failure to investigate, not a result
    max_line_search_halvings: int = 30
    model_ratio: float = 0.1  # a step gaining less than this share of the model's decrease tries shorter ones (0: off)
    grasp_stiffness: float = 6e7  # N/m per kg of held cloth (1/s^2): spring from cloth to grip point
    grasp_slip: float = 2e-3  # m: held cloth farther than this from its grip point slips in the grip
    psd_projection: str = "clamp"  # "clamp" or "abs": negative membrane eigenvalues set to 0 or |.|
    pattern_growth_rings: int = 0  # a new contact pair also adds its neighbours' pairs (rings) to the pattern
    pattern_keep_solves: int = 1  # contact entries unused for this many steps are stale ...
    pattern_prune_fraction: float = 0.0  # ... and dropped once they are this share of the contact entries
    pattern_growth_iterations: int | None = None  # new contact pairs join the pattern in a solve's first N
    #   iterations, later ones wait for the next solve (their blocks replaced by a diagonal bump); None: they always
    #   join. Waiting (N = 3 until issue 35) stiffens every contact that forms late in a solve: its Newton steps
    #   fall short, pass the step-size test, and landing cloth loses its momentum (docs/simulator.md, "Fast folds")
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
        """Check every setting (ValueError naming the field and the value); values are kept as given."""
        _real(self, "dt", 0.0, None, low_open=True, unit="s")
        gravity = self.gravity
        if (isinstance(gravity, (str, bytes)) or not hasattr(gravity, "__len__") or len(gravity) != 3
                or not all(_is_real(g) and math.isfinite(g) for g in gravity)):
            raise ValueError(f"gravity must be 3 finite numbers (m/s^2), got {gravity!r}")
        _real(self, "newton_tol", 0.0, None, low_open=True, unit="m/s")
        _integer(self, "newton_window", 1)
        if self.force_tol is not None:
            _real(self, "force_tol", 0.0, None, low_open=True, unit="m/s", extra=" or None (off)")
        _integer(self, "max_newton_iterations", 1)
        _integer(self, "max_line_search_halvings", 1, 1074)  # 0.5**n must stay > 0
        _real(self, "model_ratio", 0.0, 1.0, high_open=True)
        _real(self, "grasp_stiffness", 0.0, None, low_open=True, unit="1/s^2")
        _real(self, "grasp_slip", 0.0, None, low_open=True, unit="m")
        _choice(self, "psd_projection", ("clamp", "abs"))
        _integer(self, "pattern_growth_rings", 0)
        _integer(self, "pattern_keep_solves", 1)
        _real(self, "pattern_prune_fraction", 0.0, 1.0)
        if self.pattern_growth_iterations is not None:
            _integer(self, "pattern_growth_iterations", 1)
        _choice(self, "linear_solver", ("pardiso", "superlu", "auto"))
        _choice(self, "linear_precision", ("mixed", "double"))
        for name in ("xi", "dhat"):
            if getattr(self, name) is not None:
                _real(self, name, 0.0, None, low_open=True, unit="m", extra=" or None (the cloth thickness)")
        _real(self, "ccd_fraction", 0.0, 1.0, low_open=True)
        _real(self, "eps_v", 0.0, None, low_open=True, unit="m/s")
        _real(self, "broad_phase_reuse", 0.0, None, unit="m")
        _real(self, "table_margin", 0.0, None, unit="m")
        shifts = self.regularization_shifts
        if (isinstance(shifts, (str, bytes)) or not hasattr(shifts, "__iter__")
                or not all(_is_real(a) and math.isfinite(a) for a in shifts)
                or any(not a < b for a, b in zip((0.0, *shifts), shifts))):
            raise ValueError(f"regularization_shifts must be finite, positive and increasing, got {shifts!r}")
        _real(self, "subspace_threshold", 0.0, None, unit="m/s")
        _integer(self, "subspace_start", 1)
        _integer(self, "subspace_rings", 0)
        _real(self, "subspace_max_share", 0.0, 1.0, low_open=True)
        if not isinstance(self.check_intersections, (bool, np.bool_)):
            raise ValueError(f"check_intersections must be True or False, got {self.check_intersections!r}")
        for name in ("threads", "ccd_threads", "solver_threads"):
            _integer(self, name, 1)


def _is_real(value: object) -> bool:
    """A real number (Python or NumPy), not a bool (NumPy's bool_ is no numbers.Real)."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _real(cfg: SimConfig, name: str, low: float | None, high: float | None, *, low_open: bool = False,
          high_open: bool = False, unit: str = "", extra: str = "") -> None:
    """Field `name` is a finite real number in the interval low..high (open ends as flagged)."""
    value = getattr(cfg, name)
    ok = _is_real(value) and math.isfinite(value)
    if ok and low is not None:
        ok = value > low if low_open else value >= low
    if ok and high is not None:
        ok = value < high if high_open else value <= high
    if not ok:
        if low is not None and high is not None:
            rng = f"in {'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"
        else:
            rng = f"{'>' if low_open else '>='} {low:g}"
        raise ValueError(f"{name} must be a finite number {rng}{' ' + unit if unit else ''}{extra}, got {value!r}")


def _integer(cfg: SimConfig, name: str, low: int, high: int | None = None) -> None:
    """Field `name` is an integer (not a bool) in low..high."""
    value = getattr(cfg, name)
    if (not isinstance(value, numbers.Integral) or isinstance(value, bool) or value < low
            or (high is not None and value > high)):
        most = "" if high is None else f" and <= {high}"
        raise ValueError(f"{name} must be >= {low}{most} (an integer), got {value!r}")


def _choice(cfg: SimConfig, name: str, allowed: tuple[str, ...]) -> None:
    """Field `name` is one of the strings `allowed` (exact, case-sensitive)."""
    value = getattr(cfg, name)
    if not isinstance(value, str) or value not in allowed:
        raise ValueError(f"{name} must be one of {', '.join(map(repr, allowed))}, got {value!r}")
