"""The IPC cloth simulator: implicit Euler, projected Newton, CCD-bounded line search.

One `step` advances the cloth by dt with the grasped vertices following their grippers'
poses at the end of the step (hard constraints). Every accepted step is checked
intersection-free; a step that cannot be solved raises `SimulationFailure` and leaves
the state of the last good step untouched. Units: SI, table frame (z up, table z = 0).
"""
from __future__ import annotations

import time
from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..materials import Material
from ..pose import Pose
from . import bending, membrane
from .assembly import UpperPattern, element_dofs, scatter_gradient
from .config import SimConfig
from .contact import ContactModel
from .grasp import Grasp, grasp
from .linear_solver import SPDSolver


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
        if not friction >= 0:
            raise ValueError(f"friction coefficient must be >= 0, got {friction}")
        rest = x.copy() if rest is None else np.asarray(rest, dtype=float)
        self.material = material
        self.friction = float(friction)
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
        self._lam, self._mu = material.lame
        self._hinges = bending.hinges(tri)
        self._theta_rest, self._hinge_weight = bending.rest_state(rest, self._hinges)
        self._k_bend = material.bending_stiffness

        # Lumped masses (kg): a third of each triangle's mass per vertex.
        vm = np.bincount(tri.ravel(), weights=np.repeat(area * material.areal_density / 3, 3), minlength=n)
        if np.any(vm <= 0):
            raise ValueError("mesh has vertices that belong to no triangle")
        self.vertex_mass = vm
        self._mass_dof = np.repeat(vm, 3)
        self._gravity = np.asarray(cfg.gravity, dtype=float)

        self._tri_dofs = element_dofs(tri)
        self._hinge_dofs = element_dofs(self._hinges)
        self._pattern = UpperPattern(self.ndof, [self._tri_dofs, self._hinge_dofs])
        xi = material.thickness if cfg.xi is None else cfg.xi
        dhat = material.thickness if cfg.dhat is None else cfg.dhat
        self.contact = ContactModel(rest, tri, xi, dhat, friction, cfg.eps_v, cfg.dt)
        self.grasps: dict[int, Grasp] = {}
        self._solver = SPDSolver()
        import ipctk

        ipctk.set_num_threads(cfg.threads)
        if self.contact.intersects(self.x):
            raise ValueError("initial cloth state intersects itself or the table")

    # -- grippers ------------------------------------------------------------------------
    def grasp(self, gripper: int, pose: Pose) -> np.ndarray:
        """Close `gripper` at `pose`: attach the cloth in its grasp box; returns vertex ids."""
        if gripper in self.grasps:
            raise ValueError(f"gripper {gripper} is already closed")
        g = grasp(self.x, self.triangles, pose)
        held = self.grasped_vertex_ids()
        if np.intersect1d(held, g.vertex_ids).size:
            raise ValueError(f"gripper {gripper} would grasp vertices another gripper holds")
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
    def _elastic(self, x: np.ndarray, want_hess: bool):
        if want_hess:
            em, gm, hm = membrane.membrane_derivatives(x, self.triangles, self._shape, self._volume, self._lam, self._mu)
        else:
            em = membrane.membrane_energy(x, self.triangles, self._shape, self._volume, self._lam, self._mu)
            gm = hm = None
        eb, gb, hb = bending.bending_derivatives(
            x, self._hinges, self._theta_rest, self._hinge_weight, self._k_bend, want_hess
        )
        return em + eb, gm, hm, gb, hb

    def _energy(self, x, x_hat, x_prev, col, pull=None) -> float:
        h2 = self.dt**2
        d = (x - x_hat).ravel()
        e_el = self._elastic(x, False)[0]
        e = 0.5 * d @ (self._mass_dof * d) + h2 * e_el + self.contact.energy(col, x, x - x_prev)
        if pull is not None:
            e += 0.5 * float(pull[0] @ np.sum((x - pull[1]) ** 2, axis=1))
        return e

    # -- stepping -------------------------------------------------------------------------
    def step(self, gripper_poses: dict[int, Pose] | None = None) -> StepStats:
        """Advance by dt; `gripper_poses` gives each closed gripper's pose at the step's end.

        Grasped vertices go straight to their targets when that move is collision-free;
        otherwise they are pulled there by a stiff spring (all vertices free, so the
        barrier pushes the cloth in the way aside) and then pinned (see _move_grasped).
        """
        cfg = self.config
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

        fixed = self.grasped_vertex_ids()
        free = np.ones(len(x_prev), dtype=bool)
        free[fixed] = False
        x = x_prev.copy()
        bc = x_prev.copy()
        for gid, g in self.grasps.items():
            z = float(poses[gid].position[2])
            if z < 0.0:
                raise SimulationFailure(f"{when}: gripper {gid} commanded below the table top (z = {z * 1000:.1f} mm)")
            bc[g.vertex_ids] = g.targets(poses[gid])
        if fixed.size:
            # The table stops grasped cloth too: a grasped vertex whose rigid target lies
            # below its resting height (xi + dhat above the table) is held at that height.
            # Without this, the start of a fold's rotation about the fold line swings the
            # inner edge of the grasped patch into the table before the gripper has risen.
            floor = self.contact.xi + self.contact.dhat
            bc[fixed, 2] = np.maximum(bc[fixed, 2], np.minimum(floor, x_prev[fixed, 2]))

        if self.contact.kappa == 0.0:
            _, gm, _, gb, _ = self._elastic(x, True)
            g_el = scatter_gradient(self.ndof, self._tri_dofs, gm) + scatter_gradient(self.ndof, self._hinge_dofs, gb)
            g_e = self._mass_dof * (x - x_hat).ravel() + h * h * g_el
            self.contact.init_kappa(x, g_e, float(self.vertex_mass.mean()))
        tic = time.perf_counter()
        self.contact.lag_friction(x_prev)
        phases["friction_lag"] += time.perf_counter() - tic

        iterations = halvings = 0
        if fixed.size:
            x, it, hv = self._move_grasped(x, x_prev, x_hat, fixed, bc, phases, when)
            iterations += it
            halvings += hv
        x, it, hv, residual, col = self._newton(x, x_prev, x_hat, free, phases, when)
        iterations += it
        halvings += hv
        if cfg.check_intersections:
            tic = time.perf_counter()
            if self.contact.intersects(x):
                raise SimulationFailure(f"{when}: step ended with an intersection")
            phases["intersection_check"] += time.perf_counter() - tic
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
        )

    def _move_grasped(self, x, x_prev, x_hat, fixed, bc, phases, when):
        """Bring grasped vertices to their targets bc[fixed] without any intersection.

        The straight move is taken when CCD allows it. Otherwise a spring energy
        k/2 sum m_i |x_i - bc_i|^2 on the grasped vertices (k raised 10x per round, the
        penalty stage of an augmented-Lagrangian treatment of moving boundary conditions)
        pulls them along while the whole cloth is solved, until the last gap can be
        closed by a collision-free straight move or is below `grasp_tolerance` (the
        augmented-Lagrangian convergence test). Returns (x, iterations, halvings).
        """
        cfg = self.config
        iterations = halvings = 0
        all_free = np.ones(len(x), dtype=bool)
        k = cfg.grasp_spring
        for _ in range(cfg.max_bc_stages + 1):
            trial = x.copy()
            trial[fixed] = bc[fixed]
            tic = time.perf_counter()
            alpha = self.contact.max_step(x, trial)
            phases["ccd"] += time.perf_counter() - tic
            if alpha >= 1.0 and self.contact.separated(self.contact.build(trial), trial):
                return trial, iterations, halvings
            if iterations and np.abs(x[fixed] - bc[fixed]).max() <= cfg.grasp_tolerance:
                return x, iterations, halvings  # pinned within tolerance where the spring left it
            weight = np.zeros(len(x))
            weight[fixed] = k * self.vertex_mass[fixed]
            x, it, hv, _, _ = self._newton(x, x_prev, x_hat, all_free, phases, when, pull=(weight, bc))
            iterations += it
            halvings += hv
            k *= 10.0
        gap = float(np.abs(x[fixed] - bc[fixed]).max())
        raise SimulationFailure(
            f"{when}: the gripper motion drives the cloth into itself or the table "
            f"(grasped cloth stays {gap * 1000:.2f} mm from the gripper)"
        )

    def _newton(self, x, x_prev, x_hat, free, phases, when, pull=None):
        """Projected Newton on the free vertices; returns (x, iterations, halvings, residual, collisions).

        pull = (per-vertex spring weight (N,), anchor positions (N, 3)) adds the energy
        1/2 sum w_i |x_i - anchor_i|^2.
        """
        cfg = self.config
        h = self.dt
        free_idx = np.nonzero(np.repeat(free, 3))[0]
        residuals: list[float] = []
        halvings = 0
        prev_min = np.inf
        col = None  # collisions at x, carried over from the line search
        for it in range(1, cfg.max_newton_iterations + 1):
            if col is None:
                tic = time.perf_counter()
                col = self.contact.build(x)
                phases["collisions"] += time.perf_counter() - tic
            tic = time.perf_counter()
            u = x - x_prev
            _, gm, hm, gb, hb = self._elastic(x, True)
            phases["elastic"] += time.perf_counter() - tic
            tic = time.perf_counter()
            grad = self._mass_dof * (x - x_hat).ravel()
            grad += h * h * (
                scatter_gradient(self.ndof, self._tri_dofs, gm) + scatter_gradient(self.ndof, self._hinge_dofs, gb)
            )
            diag = self._mass_dof
            if pull is not None:
                w3 = np.repeat(pull[0], 3)
                grad += w3 * (x - pull[1]).ravel()
                diag = diag + w3
            hess = self._pattern.assemble([h * h * hm, h * h * hb], diag)
            phases["assembly"] += time.perf_counter() - tic
            tic = time.perf_counter()
            grad += self.contact.gradient(col, x, u)
            hc = self.contact.hessian(col, x, u)
            if hc is not None:
                hess = hess + sp.triu(hc, format="csr")
            phases["contact_derivatives"] += time.perf_counter() - tic
            tic = time.perf_counter()
            h_ff = hess[free_idx][:, free_idx]
            try:
                p_f = self._solver.solve(h_ff, -grad[free_idx])
            except np.linalg.LinAlgError as err:
                raise SimulationFailure(f"{when}: linear solve failed: {err}") from err
            phases["linear_solve"] += time.perf_counter() - tic
            if not np.all(np.isfinite(p_f)):
                raise SimulationFailure(f"{when}: Newton direction is not finite")
            p = np.zeros(self.ndof)
            p[free_idx] = p_f
            p = p.reshape(-1, 3)
            residual = float(np.sqrt(np.mean(np.sum(p[free] ** 2, axis=1)))) / h if free.any() else 0.0
            residuals.append(residual)
            if len(residuals) >= cfg.newton_window and max(residuals[-cfg.newton_window :]) <= cfg.newton_tol:
                return x, it, halvings, residual, col
            # Line search: CCD bound, then backtracking on the incremental potential.
            tic = time.perf_counter()
            cand = self.contact.sweep_candidates(x, x + p)  # one broad phase for CCD and line search
            alpha = min(1.0, self.contact.max_step(x, x + p, cand))
            phases["ccd"] += time.perf_counter() - tic
            if alpha <= 0.0:
                raise SimulationFailure(f"{when}: CCD allows no step (contact locked)")
            tic = time.perf_counter()
            e0 = self._energy(x, x_hat, x_prev, col, pull)
            while True:
                trial = x + alpha * p
                col_t = self.contact.build(trial, cand)
                if self.contact.separated(col_t, trial) and self._energy(trial, x_hat, x_prev, col_t, pull) <= e0:
                    break
                alpha *= 0.5
                halvings += 1
                if alpha < 0.5**cfg.max_line_search_halvings:
                    raise SimulationFailure(f"{when}: line search stalled (Newton iteration {it})")
            phases["line_search"] += time.perf_counter() - tic
            x = trial
            col = col_t
            min_d = self.contact.min_distance(col_t, x)
            if np.isfinite(min_d):
                self.contact.update_kappa(prev_min if np.isfinite(prev_min) else min_d, min_d)
            prev_min = min_d
        raise SimulationFailure(
            f"{when}: Newton did not converge in {cfg.max_newton_iterations} iterations "
            f"(residual {residuals[-1]:.3g} m/s)"
        )
