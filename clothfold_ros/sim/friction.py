"""Lagged smoothed Coulomb friction, evaluated by numba kernels on arrays read once per step.

Friction is lagged: at the start of a step ipctk's `TangentialCollisions` fix, for every
contact, its stencil's vertices, the tangent basis T (3x2) and relative-velocity Jacobian
G (3 x 3k) at the contact's closest point, its normal force lambda and weight w. Contacts
with the table (the plane z = 0) are not exposed by ipctk's Python API; their stencil is
one vertex with T the xy-plane and lambda the table barrier's normal force, computed here
the same way (`table_normal_forces`). Every Newton iteration then needs the friction
potential, gradient and Hessian for the displacement u since the step's start, which this
module evaluates per contact from P = T^T G (2 x 12, zero-padded) and c = w mu lambda:

    tau = P u_stencil,  y = |tau|,  D = c f0(y),  grad D = c f1(y)/y P^T tau,
    hess D = c P^T (f1/y I + (f1' - f1/y) / y^2 tau tau^T) P,

with IPC's smoothed f0 (y^2/eps - y^3/(3 eps^2) + eps/3 below eps = eps_v dt, y beyond).
The 2x2 middle matrix has eigenvalues f1' >= 0 and f1/y > 0, so the Hessian is positive
semi-definite without projection. Units: SI; energies in the incremental potential's units.

Sliding overshoot: beyond eps the curvature along tau is zero (f1' = 0), so where the
friction force is large against what else holds a vertex (its mass / dt^2 on the table)
the Newton step carries it from tau to about -tau, past the sticking point tau = 0, and
back: a two-cycle whose energy change is nil, hidden in the decrease of the rest of the
cloth (a 1-s sleeve fold at 3K hit the Newton cap so, a vertex on the table jumping
+-9.75 mm for 370 iterations). A contact whose tangential displacement reverses while
sliding (tau . tau_previous < 0, both beyond eps) is marked for the rest of the step and
gets c f1/y P^T P instead (the curvature f1/y along tau as across it, as iteratively
reweighted least squares does for a norm): its step then ends short of the sticking point
instead of past it. Contacts that never reverse keep the exact Hessian.
"""
from __future__ import annotations

import numba as nb
import numpy as np

STENCIL = 4  # vertices per contact stencil (fewer are padded with -1)
_CLOTH_CONTACTS = ("vv_collisions", "ev_collisions", "ee_collisions", "fv_collisions")


def clamped_log_barrier_derivative(s: np.ndarray, s_hat: float) -> np.ndarray:
    """d/ds of -(s - s_hat)^2 ln(s / s_hat) for 0 < s < s_hat, 0 beyond (ipctk's ClampedLogBarrier)."""
    s = np.asarray(s, dtype=float)
    out = np.zeros_like(s)
    m = (s > 0) & (s < s_hat)
    out[m] = (s_hat - s[m]) * (2.0 * np.log(s[m] / s_hat) - s_hat / s[m] + 1.0)
    return out


def table_normal_forces(z: np.ndarray, stiffness: float, xi: float, dhat: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices within the table barrier's range at heights z (N,) (m) and their normal forces.

    ipctk's barrier acts on the squared distance beyond the offset, kappa B(z^2 - xi^2) with
    range 2 xi dhat + dhat^2, so lambda = -kappa dB/dz = -2 z kappa B'.
    """
    z = np.asarray(z, dtype=float)
    near = np.flatnonzero((z > xi) & (z < xi + dhat))
    zn = z[near]
    return near, -2.0 * zn * stiffness * clamped_log_barrier_derivative(zn * zn - xi * xi, 2.0 * xi * dhat + dhat * dhat)


def _stencil_ids(name: str, group, edges: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Stencil vertex ids (n, 4) of one kind of ipctk tangential collision, in ipctk's
    vertex_ids order, padded with -1."""
    ids = np.full((len(group), STENCIL), -1, dtype=np.int64)
    if name == "vv_collisions":
        ids[:, 0] = [cc.vertex0_id for cc in group]
        ids[:, 1] = [cc.vertex1_id for cc in group]
    elif name == "ev_collisions":
        ids[:, 0] = [cc.vertex_id for cc in group]
        ids[:, 1:3] = edges[[cc.edge_id for cc in group]]
    elif name == "ee_collisions":
        ids[:, 0:2] = edges[[cc.edge0_id for cc in group]]
        ids[:, 2:4] = edges[[cc.edge1_id for cc in group]]
    else:  # fv_collisions
        ids[:, 0] = [cc.vertex_id for cc in group]
        ids[:, 1:4] = faces[[cc.face_id for cc in group]]
    return ids


def _read_group(name: str, group, edges: np.ndarray, faces: np.ndarray):
    """ids (n, 4), P = T^T G (n, 2, 12) zero-padded and w lambda (n,) of one kind of contact."""
    n = len(group)
    P = np.zeros((n, 2, 3 * STENCIL))
    if n == 0:
        return np.zeros((0, STENCIL), dtype=np.int64), P, np.zeros(0)
    ids = _stencil_ids(name, group, edges, faces)
    T = np.array([cc.tangent_basis for cc in group])  # (n, 3, 2)
    G = np.array([cc.relative_velocity_jacobian() for cc in group])  # (n, 3, 3k)
    P[:, :, :G.shape[2]] = np.matmul(T.transpose(0, 2, 1), G)
    c = np.array([cc.weight for cc in group]) * np.array([cc.normal_force_magnitude for cc in group])
    return ids, P, c


class LaggedFriction:
    """The friction contacts of one step as arrays: stencil vertex ids (n, 4), P (n, 2, 12)
    and c = w mu lambda (n,)."""

    def __init__(self, eps_u: float) -> None:
        self.eps = float(eps_u)  # m: slip displacement under which friction is smoothed (eps_v dt)
        self.ids = np.full((0, STENCIL), -1, dtype=np.int64)
        self.P = np.zeros((0, 2, 3 * STENCIL))
        self.c = np.zeros(0)
        self.generation = 0  # counts lags: a new set of contacts
        self._tau = np.zeros((0, 2))  # tangential displacement of each contact at the last hessians() call
        self.damped = np.zeros(0, dtype=np.bool_)  # contacts that reversed while sliding in this step

    def __len__(self) -> int:
        return len(self.c)

    def lag(self, tangential, mesh, mu: float, table_vertices: np.ndarray, table_forces: np.ndarray) -> None:
        """Read ipctk's cloth-cloth tangential collisions (built at the lag positions with the
        Coulomb coefficient mu) and add the table contacts of `table_vertices` with normal
        forces `table_forces`. About 6 us per contact (ipctk's Python accessors), once a step."""
        n_table = len(table_vertices)
        if len(table_forces) != n_table:
            raise ValueError(f"{len(table_forces)} table forces for {n_table} table vertices")
        edges, faces = mesh.edges, mesh.faces
        groups = [_read_group(name, getattr(tangential, name), edges, faces) for name in _CLOTH_CONTACTS]
        table_ids = np.full((n_table, STENCIL), -1, dtype=np.int64)
        table_ids[:, 0] = table_vertices
        table_P = np.zeros((n_table, 2, 3 * STENCIL))
        table_P[:, 0, 0] = table_P[:, 1, 1] = 1.0  # tangent basis of the table: x and y
        ids = np.concatenate([g[0] for g in groups] + [table_ids])
        P = np.concatenate([g[1] for g in groups] + [table_P])
        c = np.concatenate([g[2] for g in groups] + [np.asarray(table_forces, dtype=float)])
        self.ids, self.P, self.c = ids, P, mu * c  # ipctk's mu_s = mu_k = mu
        self._tau = np.zeros((len(c), 2))
        self.damped = np.zeros(len(c), dtype=np.bool_)
        self.generation += 1

    def energy(self, u: np.ndarray) -> float:
        """Friction potential for displacements u (N, 3) since the lag."""
        return float(_derivatives(u, self.ids, self.P, self.c, self.eps, 0)[0]) if len(self) else 0.0

    def gradient(self, u: np.ndarray) -> np.ndarray:
        """Gradient (3N,) for displacements u (N, 3)."""
        g = np.zeros(u.size)
        if len(self):
            _, grads, _ = _derivatives(u, self.ids, self.P, self.c, self.eps, 1)
            _scatter_gradient(g, self.ids, grads)
        return g

    def hessians(self, u: np.ndarray) -> np.ndarray:
        """Per-contact Hessians (n, 12, 12) on the stencils' DOFs (vertex-major xyz); contacts
        that reversed while sliding since the lag get the overshoot-free form (module doc)."""
        return _hessians(u, self.ids, self.P, self.c, self.eps, self._tau, self.damped)


@nb.njit(cache=True, inline="always")
def _tangential(u, ids, P, i):
    """tau = P u_stencil of contact i (its two tangential displacement components, m)."""
    t0 = 0.0
    t1 = 0.0
    for a in range(4):
        v = ids[i, a]
        if v < 0:
            continue
        for r in range(3):
            t0 += P[i, 0, 3 * a + r] * u[v, r]
            t1 += P[i, 1, 3 * a + r] * u[v, r]
    return t0, t1


@nb.njit(cache=True)
def _derivatives(u, ids, P, c, eps, order):
    """Energy, per-contact gradients (n, 12) (order >= 1) and Hessians (n, 12, 12) (order 2)."""
    n = ids.shape[0]
    grads = np.zeros((n if order >= 1 else 0, 12))
    hess = np.zeros((n if order >= 2 else 0, 12, 12))
    energy = 0.0
    w = np.empty((2, 12))
    for i in range(n):
        t0, t1 = _tangential(u, ids, P, i)
        y = np.sqrt(t0 * t0 + t1 * t1)
        if y < eps:
            f0 = -y * y * y / (3.0 * eps * eps) + y * y / eps + eps / 3.0
            f1y = 2.0 / eps - y / (eps * eps)
            rank = -1.0 / (eps * eps * y) if y > 0.0 else 0.0
        else:
            f0 = y
            f1y = 1.0 / y
            rank = -1.0 / (y * y * y)
        ci = c[i]
        energy += ci * f0
        if order >= 1:
            g0 = ci * f1y * t0
            g1 = ci * f1y * t1
            for k in range(12):
                grads[i, k] = P[i, 0, k] * g0 + P[i, 1, k] * g1
        if order >= 2:
            m00 = ci * (f1y + rank * t0 * t0)
            m01 = ci * rank * t0 * t1
            m11 = ci * (f1y + rank * t1 * t1)
            for k in range(12):
                w[0, k] = m00 * P[i, 0, k] + m01 * P[i, 1, k]
                w[1, k] = m01 * P[i, 0, k] + m11 * P[i, 1, k]
            for k in range(12):
                pk0 = P[i, 0, k]
                pk1 = P[i, 1, k]
                if pk0 == 0.0 and pk1 == 0.0:
                    continue
                for l in range(12):
                    hess[i, k, l] = pk0 * w[0, l] + pk1 * w[1, l]
    return energy, grads, hess


@nb.njit(cache=True)
def _hessians(u, ids, P, c, eps, tau_prev, damped):
    """Hessians (n, 12, 12); updates tau_prev (n, 2) and the sticky `damped` mask (n,)."""
    hess = _derivatives(u, ids, P, c, eps, 2)[2]
    for i in range(ids.shape[0]):
        t0, t1 = _tangential(u, ids, P, i)
        p0, p1 = tau_prev[i, 0], tau_prev[i, 1]
        if (t0 * p0 + t1 * p1 < 0.0 and t0 * t0 + t1 * t1 > eps * eps and p0 * p0 + p1 * p1 > eps * eps):
            damped[i] = True
        tau_prev[i, 0], tau_prev[i, 1] = t0, t1
        if damped[i]:
            y = np.sqrt(t0 * t0 + t1 * t1)
            s = c[i] * ((2.0 / eps - y / (eps * eps)) if y < eps else 1.0 / y)
            for k in range(12):
                for l in range(12):
                    hess[i, k, l] = s * (P[i, 0, k] * P[i, 0, l] + P[i, 1, k] * P[i, 1, l])
    return hess


@nb.njit(cache=True)
def _scatter_gradient(g, ids, grads):
    """g[3 v + r] += grads[i, 3 a + r] for every stencil vertex v = ids[i, a] >= 0, in order."""
    for i in range(ids.shape[0]):
        for a in range(4):
            v = ids[i, a]
            if v >= 0:
                for r in range(3):
                    g[3 * v + r] += grads[i, 3 * a + r]


@nb.njit(cache=True)
def scatter_stencil_hessians(data, block_slots, hess):
    """Add per-contact Hessians (n, 12, 12) into block values `data` (9 per 3x3 block):
    block (a, b) of contact i goes to block slot block_slots[i, a, b] (-1: not stored,
    i.e. a lower block whose mirror is stored, or a padded vertex). Serial, in order."""
    for i in range(hess.shape[0]):
        for a in range(4):
            for b in range(4):
                s = block_slots[i, a, b]
                if s < 0:
                    continue
                base = 9 * s
                for r in range(3):
                    for q in range(3):
                        data[base + 3 * r + q] += hess[i, 3 * a + r, 3 * b + q]
