"""The IPC cloth simulator: implicit Euler, projected Newton, CCD-bounded line search.

One `step` advances the cloth by dt, with the grasped cloth pulled by stiff springs to
grip points that follow the grippers' poses at the end of the step (grasp.py). Every
step is one Newton solve of the incremental potential over all vertices, on a Hessian
pattern that persists across iterations (pattern.py) so the sparse factorization only
re-analyses when a new contact pair appears. Every accepted step is checked
intersection-free; a step that cannot be solved raises `SimulationFailure` and leaves
the state of the last good step untouched. Units: SI, table frame (z up, table z = 0).
"""
from __future__ import annotations

import time
from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..arrays import finite_array
from ..materials import Material
from ..pose import Pose
from . import bending, membrane
from .config import SimConfig
from .contact import ContactModel
from .friction import scatter_stencil_hessians
from .grasp import Grasp, grasp
from .linear_solver import spd_solver
from .pattern import HessianPattern, element_dofs, scatter_gradient
from .subspace import ElementSubset, Subsystem, active_vertices, element_subset, subsystem


class SimulationFailure(RuntimeError):
    """A step could not be solved; `reason` says why."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


@dataclass
class StepStats:
    """What one step cost and found."""

    time: float  # s, simulated time at the end of the step
    newton_iterations: int
    line_search_halvings: int
    contacts: int  # active barrier collisions at the end of the step
    min_distance: float  # m, smallest active contact distance (inf: none)
    kappa: float
    residual: float  # m/s, RMS(|dx|)/dt of the last Newton direction
    wall_time: float  # s
    grasp_lag: float = 0.0  # m, largest distance of held cloth from its grip point at the step's end
    slipped: int = 0  # held vertices that slipped in the grip this step (lag > SimConfig.grasp_slip)
    analyses: int = 0  # symbolic factorizations (new sparsity pattern) this step
    solver_fallbacks: int = 0  # Newton systems factorized in double because single precision failed
    regularized: int = 0  # Newton systems factorized only with a diagonal shift (SimConfig.regularization_shifts)
    phases: dict[str, float] = field(default_factory=dict)  # s per phase


class ClothSimulator:
    """A single-layer cloth on a table, with grippers that grasp and move it."""

    def __init__(
        self,
        vertices: np.ndarray,
        triangles: np.ndarray,
        material: Material,
        friction: float = 0.5,
        config: SimConfig | None = None,
        rest: np.ndarray | None = None,
    ) -> None:
        self.config = config or SimConfig()
        cfg = self.config
        x = np.array(vertices, dtype=float)
        tri = np.asarray(triangles, dtype=np.int64)
        if x.ndim != 2 or x.shape[1] != 3 or not np.all(np.isfinite(x)):
            raise ValueError("vertices must be a finite (N, 3) array in metres")
        if tri.ndim != 2 or tri.shape[1] != 3 or tri.min() < 0 or tri.max() >= len(x):
            raise ValueError("triangles must be (M, 3) vertex ids into vertices")
        if not (np.isfinite(friction) and friction >= 0):
            raise ValueError(f"friction coefficient must be finite and >= 0, got {friction}")
        rest = x.copy() if rest is None else finite_array(rest, "rest shape (m)", x.shape)
        self.material = material
        self.friction_coefficient = float(friction)
        self.triangles = tri
        self.x = x
        self.v = np.zeros_like(x)
        self.time = 0.0
        self.dt = cfg.dt
        n = len(x)
        self.ndof = 3 * n

        # Membrane (neo-Hookean) and bending (hinges) from the rest shape.
        self._shape, area = membrane.rest_shape(rest, tri)
        self._volume = area * material.thickness
        self._lame_lambda, self._lame_mu = material.lame
        self._hinges = bending.hinges(tri)
        self._theta_rest, self._hinge_weight = bending.rest_state(rest, self._hinges)
        self._k_bend = material.bending_stiffness

        # Lumped masses (kg): a third of each triangle's mass per vertex.
        vm = np.bincount(tri.ravel(), weights=np.repeat(area * material.areal_density / 3, 3), minlength=n)
        if not np.all(vm > 0):
            raise ValueError("mesh has vertices that belong to no triangle")
        self.vertex_mass = vm
        self._mass_dof = np.repeat(vm, 3)
        self._gravity = np.asarray(cfg.gravity, dtype=float)

        self._tri_dofs = element_dofs(tri)
        self._hinge_dofs = element_dofs(self._hinges)
        self._pattern = HessianPattern(self.ndof, [self._tri_dofs, self._hinge_dofs], tri, cfg.pattern_growth_rings,
                                       cfg.pattern_keep_solves, cfg.pattern_prune_fraction)
        self._pattern_version = -1  # pattern version the solver has analysed
        self.fallback_directions = 0  # Newton steps that fell back to the scaled gradient
        self.regularized_solves = 0  # factorizations retried with a diagonal shift
        self.subspace_solves = 0  # Newton directions solved on the moving vertices only
        self._friction_key = None  # (friction contacts, pattern version) of _friction_cache
        self._friction_cache = np.zeros((0, 4, 4), dtype=np.int64)
        xi = material.thickness if cfg.xi is None else cfg.xi
        dhat = material.thickness if cfg.dhat is None else cfg.dhat
        self.contact = ContactModel(rest, tri, xi, dhat, friction, cfg.eps_v, cfg.dt, cfg.broad_phase_reuse,
                                    cfg.ccd_fraction, cfg.threads, cfg.ccd_threads)
        self.grasps: dict[int, Grasp] = {}
        import ipctk

        self._solver = spd_solver(cfg.linear_solver, cfg.solver_threads, cfg.linear_precision)
        self._sub_solver = spd_solver(cfg.linear_solver, cfg.solver_threads, cfg.linear_precision)
        self._sub_analysed = None  # the subsystem whose pattern the subspace solver holds
        self._elements_of, self._elements = None, None  # the subsystem whose element subset is cached, that subset
        self._project = membrane.PROJECT_ABS if cfg.psd_projection == "abs" else membrane.PROJECT_CLAMP
        self.contact.psd = ipctk.PSDProjectionMethod.ABS if cfg.psd_projection == "abs" else ipctk.PSDProjectionMethod.CLAMP

        if self.contact.intersects(self.x):
            raise ValueError("initial cloth state intersects itself or the table")
        low = int(np.argmin(self.x[:, 2]))
        if not self.x[low, 2] > self.contact.xi:  # the table barrier is infinite at the offset: no step could start
            raise ValueError(f"initial cloth state: vertex {low} lies {self.x[low, 2] * 1e3:.4f} mm above the table, "
                             f"within the contact offset {self.contact.xi * 1e3:.4f} mm (the cloth's thickness); "
                             "start it higher (flat_start lays it at twice the thickness)")

    # -- grippers ------------------------------------------------------------------------
    def grasp(self, gripper: int, pose: Pose) -> np.ndarray:
        """Close `gripper` at `pose`: attach the cloth in its grasp box; returns vertex ids."""
        if gripper in self.grasps:
            raise ValueError(f"gripper {gripper} is already closed")
        g = grasp(self.x, self.triangles, pose)
        held = self.grasped_vertex_ids()
        shared = np.isin(g.vertex_ids, held)
        if shared.all():
            raise ValueError(f"gripper {gripper} would hold only cloth another gripper holds")
        if shared.any():  # boxes whose triangles touch: cloth already held stays with its gripper
            g = Grasp(g.vertex_ids[~shared], g.local[~shared])
        self.grasps[gripper] = g
        return g.vertex_ids

    def release(self, gripper: int) -> None:
        """Open `gripper`; its vertices move freely from now on."""
        self.grasps.pop(gripper, None)

    def grasped_vertex_ids(self) -> np.ndarray:
        if not self.grasps:
            return np.zeros(0, dtype=np.int64)
        return np.unique(np.concatenate([g.vertex_ids for g in self.grasps.values()]))

    # -- energy -------------------------------------------------------------------------
    def _elastic(self, x: np.ndarray, want_hess: bool = True, elements: ElementSubset | None = None):
        """Elastic energy (J), per-element gradients and PSD Hessians (membrane, bending), of
        every element or of the subset `elements`."""
        t, k = (slice(None), slice(None)) if elements is None else (elements.triangles, elements.hinges)
        em, gm, hm = membrane.membrane_derivatives(x, self.triangles[t], self._shape[t], self._volume[t],
                                                   self._lame_lambda, self._lame_mu, self._project, want_hess)
        eb, gb, hb = bending.bending_derivatives(
            x, self._hinges[k], self._theta_rest[k], self._hinge_weight[k], self._k_bend, want_hess
        )
        return em + eb, gm, hm, gb, hb

    def _elastic_system(self, x: np.ndarray, elements: ElementSubset | None = None):
        """h^2 x the elastic gradient (ndof,) and the element Hessians (membrane, bending) of
        every element or of `elements` (then the gradient holds only their terms)."""
        _, gm, hm, gb, hb = self._elastic(x, True, elements)
        tri_dofs, hinge_dofs = (self._tri_dofs, self._hinge_dofs) if elements is None else \
            (self._tri_dofs[elements.triangles], self._hinge_dofs[elements.hinges])
        g = self.dt**2 * (scatter_gradient(self.ndof, tri_dofs, gm) + scatter_gradient(self.ndof, hinge_dofs, gb))
        return g, [hm, hb]

    def _elastic_energy(self, x: np.ndarray) -> float:
        return membrane.membrane_energy(x, self.triangles, self._shape, self._volume, self._lame_lambda, self._lame_mu) + \
            bending.bending_energy(x, self._hinges, self._theta_rest, self._hinge_weight, self._k_bend)

    def _energy(self, x, x_hat, x_prev, col, pull=None) -> float:
        h2 = self.dt**2
        d = (x - x_hat).ravel()
        e_el = self._elastic_energy(x)
        e = 0.5 * d @ (self._mass_dof * d) + h2 * e_el + self.contact.energy(col, x, x - x_prev)
        if pull is not None:
            e += 0.5 * float(pull[0] @ np.sum((x - pull[1]) ** 2, axis=1))
        return e

    # -- stepping -------------------------------------------------------------------------
    def _grip_points(self, poses: dict[int, Pose], x_prev: np.ndarray, when: str):
        """Spring weights (N,) and grip points (N, 3) of the held cloth at the step's end.

        A grip point whose rigid position lies below the held vertex's resting height
        (xi + dhat above the table) is kept at that height: the start of a fold's rotation
        about the fold line would otherwise swing the inner edge of the grasped patch into
        the table before the gripper has risen.
        """
        weight = np.zeros(len(x_prev))
        anchor = x_prev.copy()
        k = self.dt**2 * self.config.grasp_stiffness
        for gid, g in self.grasps.items():
            z = float(poses[gid].position[2])
            if z < 0.0:
                raise SimulationFailure(f"{when}: gripper {gid} commanded below the table top (z = {z * 1000:.1f} mm)")
            anchor[g.vertex_ids] = g.targets(poses[gid])
            weight[g.vertex_ids] = k * self.vertex_mass[g.vertex_ids]
        held = weight > 0
        if held.any():
            floor = self.contact.xi + self.contact.dhat
            anchor[held, 2] = np.maximum(anchor[held, 2], np.minimum(floor, x_prev[held, 2]))
        return weight, anchor

    def _warm_start(self, x_prev: np.ndarray, weight: np.ndarray, anchor: np.ndarray, phases):
        """Newton's first iterate and its collisions (None: not built yet): held cloth at its
        grip points, cut back by CCD to an intersection-free fraction of that move; free
        cloth where it is. (Moving free cloth on at its velocity was tried: it pushes cloth
        falling onto the table deep into the barrier, where the lagged friction of the next
        step then glues it.)"""
        guess = x_prev.copy()
        held = weight > 0
        guess[held] = anchor[held]
        if np.array_equal(guess, x_prev):
            return x_prev.copy(), None
        tic = time.perf_counter()
        alpha = min(1.0, self.contact.max_step(x_prev, guess))
        phases["ccd"] += time.perf_counter() - tic
        if alpha <= 0.0:
            return x_prev.copy(), None
        x = x_prev + alpha * (guess - x_prev)
        col = self.contact.build(x)
        if not self.contact.separated(col, x):
            return x_prev.copy(), None
        return x, col

    def step(self, gripper_poses: dict[int, Pose] | None = None) -> StepStats:
        """Advance by dt; `gripper_poses` gives each closed gripper's pose at the step's end."""
        t_start = time.perf_counter()
        phases: dict[str, float] = defaultdict(float)
        poses = gripper_poses or {}
        missing = [g for g in self.grasps if g not in poses]
        if missing:
            raise ValueError(f"no pose given for closed gripper(s) {missing}")
        h = self.dt
        when = f"t={self.time + h:.3f}s"
        x_prev = self.x.copy()
        x_hat = x_prev + h * self.v + h * h * self._gravity
        weight, anchor = self._grip_points(poses, x_prev, when)
        pull = (weight, anchor) if self.grasps else None

        if self.contact.kappa == 0.0:
            _, gm, _, gb, _ = self._elastic(x_prev, False)
            g_el = scatter_gradient(self.ndof, self._tri_dofs, gm) + scatter_gradient(self.ndof, self._hinge_dofs, gb)
            g_e = self._mass_dof * (x_prev - x_hat).ravel() + h * h * g_el
            self.contact.init_kappa(x_prev, g_e, float(self.vertex_mass.mean()))
        tic = time.perf_counter()
        self.contact.lag_friction(x_prev)
        phases["friction_lag"] += time.perf_counter() - tic

        analyses0, fallbacks0, regularized0 = self._solver.analyses, self._solver.fallbacks, self.regularized_solves
        x, col = self._warm_start(x_prev, weight, anchor, phases)
        x, iterations, halvings, residual, col = self._newton(x, x_prev, x_hat, phases, when, pull, col)
        if self.config.check_intersections:
            tic = time.perf_counter()
            if self.contact.intersects(x):
                raise SimulationFailure(f"{when}: step ended with an intersection")
            phases["intersection_check"] += time.perf_counter() - tic
        lag, slipped = self._slip(x, poses, anchor)
        self.v = (x - x_prev) / h
        self.x = x
        self.time += h
        return StepStats(
            time=self.time,
            newton_iterations=iterations,
            line_search_halvings=halvings,
            contacts=len(col),
            min_distance=self.contact.min_distance(col, x),
            kappa=self.contact.kappa,
            residual=residual,
            wall_time=time.perf_counter() - t_start,
            phases=dict(phases),
            grasp_lag=lag,
            slipped=slipped,
            analyses=self._solver.analyses - analyses0,
            solver_fallbacks=self._solver.fallbacks - fallbacks0,
            regularized=self.regularized_solves - regularized0,
        )

    def _slip(self, x: np.ndarray, poses: dict[int, Pose], anchor: np.ndarray) -> tuple[float, int]:
        """Largest held-cloth lag (m); vertices lagging beyond grasp_slip slip in the grip."""
        lag_max, slipped = 0.0, 0
        for gid, g in list(self.grasps.items()):
            lag = np.linalg.norm(x[g.vertex_ids] - anchor[g.vertex_ids], axis=1)
            lag_max = max(lag_max, float(lag.max()))
            slip = lag > self.config.grasp_slip
            if slip.any():
                self.grasps[gid] = g.slipped(poses[gid], x, slip)
                slipped += int(slip.sum())
        return lag_max, slipped

    def _direction(self, data: np.ndarray, grad: np.ndarray, when: str, sub: Subsystem | None = None) -> np.ndarray:
        """Newton direction -H^-1 grad for the Hessian values `data` on the pattern; with
        `sub`, the direction of its vertices only (H_AA p_A = -g_A, the rest zero).

        The system is scaled symmetrically by its diagonal first: barrier entries near
        contact exceed the mass entries by many orders of magnitude, and unscaled the
        factorization loses so much accuracy there that the "descent" direction can point
        uphill. If it still does, the step falls back to the diagonally scaled gradient.
        A matrix that is positive definite but whose factorization still breaks down (a
        contact block some 1e16 times stiffer than the mass of its vertices: the pivot of
        their relative motion cancels to rounding) is factorized again with
        `SimConfig.regularization_shifts` times its diagonal added, the smallest that works
        (counted in `StepStats.regularized`); other systems are solved as they are.
        """
        pat = self._pattern
        if self._pattern_version != (id(pat), pat.version):
            self._solver.set_pattern(pat.indptr, pat.indices, pat.block)
            self._pattern_version = (id(pat), pat.version)
        d = data[pat.diag_slots]
        if not np.all(d > 0) or not np.all(np.isfinite(data)):
            raise SimulationFailure(f"{when}: Newton matrix has a non-positive or non-finite diagonal")
        scale = 1.0 / np.sqrt(d)
        scaled = pat.scaled(data, scale)
        if sub is None:
            p = scale * self._factor_solve(self._solver, scaled, pat.diag_slots, -scale * grad, when)
        else:
            if self._sub_analysed is not sub:
                self._sub_solver.set_pattern(sub.indptr, sub.indices, pat.block)
                self._sub_analysed = sub
            dofs = sub.dofs
            p = np.zeros(len(grad))
            p[dofs] = scale[dofs] * self._factor_solve(self._sub_solver, sub.values(scaled), sub.diag_slots,
                                                       -scale[dofs] * grad[dofs], when)
            self.subspace_solves += 1
        if not np.all(np.isfinite(p)):
            raise SimulationFailure(f"{when}: Newton direction is not finite")
        if float(grad @ p) >= 0.0:
            self.fallback_directions += 1
            p = -grad / d
            if sub is not None:
                p[~np.repeat(sub.active, 3)] = 0.0
        return p.reshape(-1, 3)

    def _element_subset(self, sub: Subsystem) -> ElementSubset:
        """The triangles and hinges touching the subsystem's vertices (cached per subsystem):
        the only elements in its rows of the Newton system and in its gradient."""
        if self._elements_of is not sub:
            self._elements = element_subset(sub.active, self.triangles, self._hinges, self._pattern.block_slots)
            self._elements_of = sub
        return self._elements

    def _subsystem(self, p: np.ndarray) -> Subsystem | None:
        """The subsystem of the vertices that the full direction p (N, 3) moves faster than
        `SimConfig.subspace_threshold` and their neighbours; None where that is most of them
        or none (a Newton tolerance below the threshold: then every direction is full)."""
        cfg, pat = self.config, self._pattern
        active = active_vertices(p, cfg.subspace_threshold * self.dt, pat.block_rows, pat.indices, cfg.subspace_rings)
        if not active.any() or active.sum() > cfg.subspace_max_share * len(active):
            return None  # nothing above the threshold (a tolerance below it) or most of the cloth
        return subsystem(pat.block_rows, pat.indices, active)

    def _factor_solve(self, solver, scaled: np.ndarray, diag_slots: np.ndarray, rhs: np.ndarray,
                      when: str) -> np.ndarray:
        """Solve the diagonally scaled system, retrying a factorization that breaks down
        with `SimConfig.regularization_shifts` (times the unit diagonal) added."""
        for shift in (0.0, *self.config.regularization_shifts):
            try:
                if shift:  # diag(A) * shift added: the factorization failed on the matrix itself
                    scaled[diag_slots] += shift - previous
                    self.regularized_solves += 1
                solver.factor(scaled)
                return solver.solve(rhs)
            except np.linalg.LinAlgError as err:
                previous, failure = shift, err
        shifts = self.config.regularization_shifts
        tried = f" (also with diagonal shifts up to {max(shifts):g} x diag)" if shifts else ""
        raise SimulationFailure(f"{when}: linear solve failed: {failure}{tried}") from failure

    def _friction_slots(self, friction) -> np.ndarray:
        """Block slots of the lagged friction contacts' stencils in the current pattern
        (recomputed when the contacts or the pattern changed; missing blocks are added)."""
        if self._friction_key != (friction.generation, self._pattern.version):
            self._friction_cache = self._pattern.stencil_block_slots(friction.ids)  # may grow: a new version
            self._friction_key = (friction.generation, self._pattern.version)
        return self._friction_cache

    def _newton(self, x, x_prev, x_hat, phases, when, pull=None, col=None):
        """Projected Newton on all vertices; returns (x, iterations, halvings, residual, collisions).

        pull = (per-vertex spring weight (N,), grip points (N, 3)) adds the grasp energy
        1/2 sum w_i |x_i - grip_i|^2.

        Stopping: the last `newton_window` full directions below `newton_tol` (RMS |dx| / dt),
        tested from the second iteration on: the first iterate (free cloth where it was) is
        never accepted as it is, since smoothed static friction's stiff curvature makes its
        Newton step short even where the cloth should slide (docs/simulator.md, "Fast folds").
        `force_tol` optionally also bounds the unbalanced force (`_force_residual`).
        """
        cfg = self.config
        h = self.dt
        h2 = h * h
        residuals: list[float] = []
        halvings = 0
        prev_min = np.inf
        # col: collisions at x (from the warm start, then carried over from the line search)
        diag = self._mass_dof if pull is None else self._mass_dof + np.repeat(pull[0], 3)
        free = None if pull is None else pull[0] == 0  # vertices no gripper holds
        energy = None  # incremental potential at x (J), from the last line search while kappa is unchanged
        full, sub, sub_version = 0, None, -1  # full directions so far; the subsystem of the moving vertices
        for it in range(1, cfg.max_newton_iterations + 1):
            if col is None:
                tic = time.perf_counter()
                col = self.contact.build(x)
                phases["collisions"] += time.perf_counter() - tic
            tic = time.perf_counter()
            u = x - x_prev
            elements = None if sub is None else self._element_subset(sub)
            g_elastic, h_elastic = self._elastic_system(x, elements)
            phases["elastic"] += time.perf_counter() - tic
            tic = time.perf_counter()
            g_inertia = self._mass_dof * (x - x_hat).ravel()
            g_pull = None if pull is None else np.repeat(pull[0], 3) * (x - pull[1]).ravel()
            g_contact = self.contact.gradient(col, x, u)

            def gradient(g_el):
                g = g_inertia + g_el
                if g_pull is not None:
                    g += g_pull
                return g + g_contact

            grad = gradient(g_elastic)
            contact = None
            hc = self.contact.hessian(col, x)
            if it == 1:  # prune stale contact entries, add the ones deferred in the last solve
                self._pattern.begin_solve()
            friction = self.contact.friction
            if len(friction):  # friction's blocks first: they may grow the pattern
                self._friction_slots(friction)
            if hc is not None:
                slots, vals, _ = self._pattern.contact_slots(hc, grow=cfg.pattern_growth_iterations is None
                                                                 or it <= cfg.pattern_growth_iterations)
                contact = (slots, vals)
            friction_hessians = friction.hessians(u) if len(friction) else None
            phases["contact_derivatives"] += time.perf_counter() - tic
            tic = time.perf_counter()

            def assemble(h_el, slots):
                data = self._pattern.assemble(h_el, h2, diag, contact, slots)
                if friction_hessians is not None:
                    scatter_stencil_hessians(data, self._friction_slots(friction), friction_hessians)
                return data

            data = assemble(h_elastic, None if elements is None else elements.block_slots)
            phases["assembly"] += time.perf_counter() - tic
            tic = time.perf_counter()
            if sub is not None and sub_version != self._pattern.version:  # the pattern grew: same vertices
                sub, sub_version = subsystem(self._pattern.block_rows, self._pattern.indices, sub.active), \
                    self._pattern.version
                self._elements_of = sub  # the same vertices: the same elements
            p = self._direction(data, grad, when, sub)
            residual = float(np.sqrt(np.mean(np.sum(p**2, axis=1)))) / h
            if sub is not None and residual <= cfg.newton_tol:  # the moving cloth has converged: check all of it
                sub = None
                phases["linear_solve"] += time.perf_counter() - tic
                tic = time.perf_counter()
                g_elastic, h_elastic = self._elastic_system(x)
                grad = gradient(g_elastic)
                data = assemble(h_elastic, None)
                phases["elastic"] += time.perf_counter() - tic
                tic = time.perf_counter()
                p = self._direction(data, grad, when)
                residual = float(np.sqrt(np.mean(np.sum(p**2, axis=1)))) / h
            full_direction = sub is None
            if full_direction:
                full += 1
                if cfg.subspace_threshold > 0 and full >= cfg.subspace_start and residual > cfg.newton_tol:
                    sub, sub_version = self._subsystem(p), self._pattern.version
            phases["linear_solve"] += time.perf_counter() - tic
            residuals.append(residual)
            if full_direction and it > 1 and len(residuals) >= cfg.newton_window and \
                    max(residuals[-cfg.newton_window :]) <= cfg.newton_tol and \
                    (cfg.force_tol is None or self._force_residual(grad, free) <= cfg.force_tol):
                return x, it, halvings, residual, col  # it > 1: the first iterate is never taken as it is (docstring)
            try:
                x_new, col_t, n_halved, energy = self._line_search(x, p, grad, x_hat, x_prev, col, pull, phases, when,
                                                                   f"Newton iteration {it}, residual {residual:.3g} m/s",
                                                                   energy)
            except SimulationFailure:
                if full_direction and residual <= cfg.newton_tol:  # a step below the tolerance that cannot be
                    return x, it, halvings, residual, col  # taken (rounding, CCD): x is as converged as it gets
                raise
            halvings += n_halved
            x = x_new
            col = col_t
            min_d = self.contact.min_distance(col_t, x)
            if np.isfinite(min_d):
                kappa = self.contact.kappa
                self.contact.update_kappa(prev_min if np.isfinite(prev_min) else min_d, min_d)
                if self.contact.kappa != kappa:
                    energy = None  # a stiffer barrier: the potential at x changed
            prev_min = min_d
        raise SimulationFailure(
            f"{when}: Newton did not converge in {cfg.max_newton_iterations} iterations "
            f"(residual {residuals[-1]:.3g} m/s)"
        )

    def _force_residual(self, grad: np.ndarray, free: np.ndarray | None) -> float:
        """RMS over the free vertices of the velocity (m/s) their unbalanced force would add in
        one step, |g_i| / (m_i h) (g is h^2 x the force); held vertices answer to their grip."""
        a = grad.reshape(-1, 3) / self.vertex_mass[:, None]
        if free is not None:
            a = a[free]
        return float(np.sqrt(np.mean(np.sum(a * a, axis=1)))) / self.dt if len(a) else 0.0

    def _line_search(self, x, p, grad, x_hat, x_prev, col, pull, phases, when: str, context: str, e0=None):
        """Step length along the Newton direction p: (new x, its collisions, halvings, its
        incremental potential). e0: the potential at x if known (the last line search's).

        CCD bounds the step (every point of the path keeps ccd_fraction x xi apart), then
        it is halved until the state is more than xi apart everywhere and the incremental
        potential does not rise. A step that gains less than model_ratio of the decrease
        its quadratic model promised, g.p (alpha - alpha^2 / 2), also tries shorter steps
        along p and keeps the best: this ends the limit cycles in which contact pairs enter
        and leave the barrier's range every iteration.
        """
        cfg = self.config
        tic = time.perf_counter()
        cand = self.contact.candidates(x, x + p)  # one candidate set for CCD and line search
        alpha = min(1.0, self.contact.max_step(x, x + p, cand))
        phases["ccd"] += time.perf_counter() - tic
        if alpha <= 0.0:
            raise SimulationFailure(f"{when}: CCD allows no step (contact locked)")
        tic = time.perf_counter()
        smallest = 0.5**cfg.max_line_search_halvings
        slope = float(grad @ p.ravel())
        if e0 is None:
            e0 = self._energy(x, x_hat, x_prev, col, pull)
        halvings = 0
        while True:
            trial = x + alpha * p
            col_t = self.contact.build(trial, cand)
            if self.contact.separated(col_t, trial):
                e_trial = self._energy(trial, x_hat, x_prev, col_t, pull)
                if e_trial <= e0:
                    break
            alpha *= 0.5
            halvings += 1
            if alpha < smallest:
                d0 = self.contact.min_distance(self.contact.build(x, cand), x)
                raise SimulationFailure(f"{when}: line search stalled ({context}; slope {slope:.3g} J, closest "
                                        f"contact {d0 * 1000:.4f} mm, offset {self.contact.xi * 1000:.4f} mm)")
        if cfg.model_ratio > 0 and e0 - e_trial < cfg.model_ratio * -slope * alpha * (1 - 0.5 * alpha):
            while alpha > smallest:
                shorter = x + 0.5 * alpha * p
                col_s = self.contact.build(shorter, cand)
                if not self.contact.separated(col_s, shorter):
                    break
                e_s = self._energy(shorter, x_hat, x_prev, col_s, pull)
                if e_s >= e_trial:
                    break
                trial, col_t, e_trial, alpha = shorter, col_s, e_s, 0.5 * alpha
                halvings += 1
        phases["line_search"] += time.perf_counter() - tic
        return trial, col_t, halvings, e_trial
