"""IPC contact: log barrier, lagged smoothed Coulomb friction and CCD, via ipctk.

The friction's per-iteration derivatives come from `friction.LaggedFriction` (numba, on
arrays read from ipctk's tangential collisions once per step).

Self-contact of the cloth and contact with the table (the plane z = 0, normal +z).
Mid-surfaces keep at least `xi` apart (ipctk's dmin) and the barrier acts within `dhat`
beyond that. Energies follow the incremental potential scaled like 1/2 |x - x_hat|_M^2,
so the barrier is kappa * B(x) and friction D(u) is built from that barrier's forces.
"""
from __future__ import annotations

from contextlib import contextmanager

import ipctk
import numpy as np
import scipy.sparse as sp

from .friction import LaggedFriction, table_normal_forces

PSD = ipctk.PSDProjectionMethod.CLAMP


class ContactModel:
    """Collision mesh, table plane and contact potentials for one cloth."""

    def __init__(
        self,
        rest: np.ndarray,
        triangles: np.ndarray,
        xi: float,
        dhat: float,
        friction: float,
        eps_v: float,
        dt: float,
        reuse_radius: float = 5e-4,
        ccd_fraction: float = 0.99,
        threads: int = 1,
        ccd_threads: int = 1,
    ) -> None:
        tri = np.asarray(triangles, dtype=np.int32)
        edges = ipctk.edges(tri)
        self.mesh = ipctk.CollisionMesh(np.asfortranarray(rest, dtype=float), edges, tri)
        self.mesh.planes = [ipctk.Hyperplane(np.array([0.0, 0.0, 1.0]), np.zeros(3))]
        self.xi = float(xi)
        self.dhat = float(dhat)
        # The barrier is singular at xi and reaches xi + dhat.
        self.barrier_dmin = self.xi
        self.barrier_dhat = self.dhat
        if not 0.0 < ccd_fraction <= 1.0:
            raise ValueError(f"ccd_fraction must be in (0, 1], got {ccd_fraction}")
        self.ccd_fraction = float(ccd_fraction)
        self.friction_coefficient = float(friction)  # Coulomb mu, every contact
        self.dt = float(dt)
        self.friction = LaggedFriction(eps_v * dt)  # the lagged contacts as arrays, evaluated per iteration
        self.narrow_phase = ipctk.AdditiveCCD()
        self.kappa = 0.0
        self.kappa_max = 0.0
        self.kappa_gap = 1e-3 * self.dhat  # m: gap beyond xi under which a closing contact stiffens kappa
        self.barrier = ipctk.BarrierPotential(self.barrier_dhat, 1.0)
        self.bbox_diagonal = float(ipctk.world_bbox_diagonal_length(np.asfortranarray(rest)))
        self.collisions = ipctk.NormalCollisions()
        self.tangential = ipctk.TangentialCollisions()
        self.psd = PSD  # projection of the barrier and friction Hessians
        # Broad-phase reuse: candidates built at reference positions with the inflation
        # grown by 2 x reuse_radius stay complete for any move that keeps every vertex
        # within reuse_radius of its reference position.
        self.reuse_radius = float(reuse_radius)
        self._cache_ref: np.ndarray | None = None
        self._cache: ipctk.Candidates | None = None
        self.broad_phases = 0  # broad-phase builds (statistics)
        self.threads = int(threads)  # ipctk threads for everything but the CCD query
        self.ccd_threads = int(ccd_threads)
        ipctk.set_num_threads(self.threads)

    # -- collision sets --------------------------------------------------------------
    def build(self, x: np.ndarray, candidates: ipctk.Candidates | None = None) -> ipctk.NormalCollisions:
        """Active barrier collisions at positions x (N, 3).

        `candidates` (from `candidates` of a move through x) skip the broad phase.
        """
        xf = np.asfortranarray(x)
        if candidates is None:
            candidates = self.candidates(x)
        col = ipctk.NormalCollisions()
        col.build(candidates, self.mesh, xf, self.barrier_dhat, self.barrier_dmin)
        return col

    def sweep_candidates(self, x0: np.ndarray, x1: np.ndarray, inflation: float = 0.0) -> ipctk.Candidates:
        """Broad-phase candidates for every point of the linear move x0 -> x1."""
        cand = ipctk.Candidates()
        cand.build(self.mesh, np.asfortranarray(x0), np.asfortranarray(x1),
                   self.barrier_dhat + self.barrier_dmin + inflation)
        self.broad_phases += 1
        return cand

    def candidates(self, x0: np.ndarray, x1: np.ndarray | None = None) -> ipctk.Candidates:
        """Candidates complete for every point of the move x0 -> x1 (x1 None: at x0).

        Reuses the cached set while both ends lie within reuse_radius of its reference
        positions (then every point of the segment does); otherwise a small move rebuilds
        the cache at x0 and a large one gets a swept broad phase of its own.
        """
        x1 = x0 if x1 is None else x1
        r2 = self.reuse_radius**2
        ref = self._cache_ref
        if ref is not None and ref.shape == x0.shape:
            if np.sum((x0 - ref) ** 2, axis=1).max() <= r2 and np.sum((x1 - ref) ** 2, axis=1).max() <= r2:
                return self._cache
        if np.sum((x1 - x0) ** 2, axis=1).max() <= 0.25 * r2:
            # two primitives each moving up to reuse_radius close in by up to twice that
            self._cache = self.sweep_candidates(x0, x0, 2.0 * self.reuse_radius)
            self._cache_ref = x0.copy()
            return self._cache
        return self.sweep_candidates(x0, x1)

    def set_kappa(self, kappa: float) -> None:
        self.kappa = float(kappa)
        self.barrier = ipctk.BarrierPotential(self.barrier_dhat, self.kappa)

    def init_kappa(self, x: np.ndarray, grad_energy: np.ndarray, avg_mass: float) -> None:
        """Choose the barrier stiffness the IPC way (balance barrier and energy gradients)."""
        col = self.build(x)
        unit = ipctk.BarrierPotential(self.barrier_dhat, 1.0)
        grad_b = unit.gradient(col, self.mesh, np.asfortranarray(x)) if len(col) else np.zeros_like(grad_energy)
        kappa, kmax = ipctk.initial_barrier_stiffness(
            self.bbox_diagonal, unit.barrier, self.barrier_dhat, avg_mass, grad_energy, grad_b, dmin=self.barrier_dmin
        )
        self.kappa_max = max(self.kappa_max, kmax)
        self.set_kappa(max(self.kappa, kappa))

    def update_kappa(self, prev_min_dist: float, min_dist: float) -> None:
        """Double kappa (up to kappa_max) while the closest contact keeps closing in on the offset.

        The test is on the gap beyond the offset, d - xi: ipctk's update_barrier_stiffness
        compares raw distances, which with an offset never come below its threshold, so the
        stiffness never grew and contacts crept to within nanometres of the singular
        barrier, where Newton crawls (steps cut to a few percent by CCD).
        """
        gap, prev_gap = min_dist - self.xi, prev_min_dist - self.xi
        if gap < self.kappa_gap and gap < prev_gap and self.kappa < self.kappa_max:
            self.set_kappa(min(self.kappa_max, 2.0 * self.kappa))

    def lag_friction(self, x: np.ndarray) -> None:
        """Fix friction normal forces and tangent bases at x (start of the step)."""
        xf = np.asfortranarray(x)
        col = self.build(x)
        self.tangential = ipctk.TangentialCollisions()
        if len(col) and self.friction_coefficient > 0:
            self.tangential.build(self.mesh, xf, col, self.barrier, self.friction_coefficient)
        near, forces = table_normal_forces(x[:, 2], self.kappa, self.xi, self.dhat)
        if self.friction_coefficient <= 0:
            near, forces = near[:0], forces[:0]
        self.friction.lag(self.tangential, self.mesh, self.friction_coefficient, near, forces)

    # -- potentials ---------------------------------------------------------------------
    def energy(self, col: ipctk.NormalCollisions, x: np.ndarray, u: np.ndarray) -> float:
        e = self.barrier(col, self.mesh, np.asfortranarray(x)) if len(col) else 0.0
        return float(e) + self.friction.energy(u)

    def gradient(self, col: ipctk.NormalCollisions, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        g = np.zeros(x.size)
        if len(col):
            g += self.barrier.gradient(col, self.mesh, np.asfortranarray(x))
        return g + self.friction.gradient(u)

    def hessian(self, col: ipctk.NormalCollisions, x: np.ndarray) -> sp.spmatrix | None:
        """The barrier's Hessian, projected per contact (None: no contact); the friction's
        per-contact Hessians come from `friction.hessians`."""
        if not len(col):
            return None
        return self.barrier.hessian(col, self.mesh, np.asfortranarray(x), self.psd)

    # -- geometry queries -------------------------------------------------------------------
    def min_distance(self, col: ipctk.NormalCollisions, x: np.ndarray) -> float:
        """Smallest distance (m) among active collisions; inf when none."""
        if not len(col):
            return np.inf
        return float(np.sqrt(col.compute_minimum_distance(self.mesh, np.asfortranarray(x))))

    def separated(self, col: ipctk.NormalCollisions, x: np.ndarray) -> bool:
        """True if every active pair is more than xi apart.

        CCD with a minimum distance works to a tolerance and can hand back a step that
        ends a hair inside xi, where the barrier is undefined; line searches reject
        such states with this check.
        """
        return self.min_distance(col, x) > self.xi

    @property
    def ccd_min_distance(self) -> float:
        """Separation the CCD keeps (m): ccd_fraction x xi.

        Additive CCD advances a pair by a fraction of its gap beyond this distance per
        iteration, so a pair resting a hair above xi (nearly parallel edges, whose barrier
        the mollifier weakens, sit within 1e-10 m of it) took millions of iterations, up to
        0.5 s per query. A 1 % margin keeps the path intersection-free and the query fast;
        the line search's `separated` check then keeps every accepted state beyond xi.
        """
        return self.ccd_fraction * self.xi

    def max_step(self, x0: np.ndarray, x1: np.ndarray, candidates: ipctk.Candidates | None = None) -> float:
        """Largest collision-free fraction of the linear move x0 -> x1 (keeps xi apart).

        ipctk's CCD covers self-contact with additive CCD (ACCD, the CCD of C-IPC; the
        default tight-inclusion CCD with a minimum distance returns uncertified tiny
        steps for nearly parallel edge pairs, which stalls Newton); the table plane is
        checked here in closed form (ipctk's step-size query does not look at planes).
        The query runs on `ccd_threads`: each pair's time of impact does not depend on the
        others, so their minimum is the same with any thread count.
        """
        if candidates is None:
            candidates = self.candidates(x0, x1)
        a, b = np.asfortranarray(x0), np.asfortranarray(x1)
        with self._ipctk_threads(self.ccd_threads):
            self_ccd = candidates.compute_collision_free_stepsize(
                self.mesh, a, b, min_distance=self.ccd_min_distance, narrow_phase_ccd=self.narrow_phase
            )
        return min(float(self_ccd), self.table_step(x0[:, 2], x1[:, 2]))

    @contextmanager
    def _ipctk_threads(self, n: int):
        """Run ipctk on n threads inside the block, on `threads` again after it."""
        if n == self.threads:
            yield
            return
        ipctk.set_num_threads(n)
        try:
            yield
        finally:
            ipctk.set_num_threads(self.threads)

    def table_step(self, z0: np.ndarray, z1: np.ndarray) -> float:
        """Largest fraction of z0 -> z1 keeping every vertex above z = xi (10 % margin)."""
        moving_down = z1 < z0
        gap = z0 - self.xi
        reach = z0 - z1
        hits = moving_down & (z1 <= self.xi + 0.1 * gap)
        if not hits.any():
            return 1.0
        return float(max(0.0, np.min(0.9 * gap[hits] / reach[hits])))

    def intersects(self, x: np.ndarray) -> bool:
        """True if the cloth intersects itself or lies below the table top."""
        return bool(ipctk.has_intersections(self.mesh, np.asfortranarray(x))) or bool(np.any(x[:, 2] < 0.0))
