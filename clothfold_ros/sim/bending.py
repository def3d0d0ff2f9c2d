"""Discrete-shell hinge bending: k (theta - theta_rest)^2 |e| / h_e per interior edge.

h_e = (A1 + A2) / (3 |e|) from the rest mesh; theta is the signed dihedral angle (0 when
flat). Hessians use the Gauss-Newton term 2 k w grad(theta) grad(theta)^T, which is PSD.
"""
from __future__ import annotations

import numba as nb
import numpy as np


def hinges(triangles: np.ndarray) -> np.ndarray:
    """Interior edges as (H, 4) vertex ids (e0, e1, opposite in tri A, opposite in tri B).

    Triangle A contains the directed edge e0 -> e1, triangle B the edge e1 -> e0 (a
    consistently oriented mesh).
    """
    tri = np.asarray(triangles, dtype=np.int64)
    m = len(tri)
    starts = tri.reshape(-1)
    ends = tri[:, [1, 2, 0]].reshape(-1)
    opp = tri[:, [2, 0, 1]].reshape(-1)
    lo, hi = np.minimum(starts, ends), np.maximum(starts, ends)
    key = lo * (tri.max() + 1) + hi
    order = np.argsort(key, kind="stable")
    k_sorted = key[order]
    same = np.nonzero(k_sorted[1:] == k_sorted[:-1])[0]
    a, b = order[same], order[same + 1]
    if len(np.unique(k_sorted)) + len(same) != 3 * m:
        raise ValueError("mesh is not a manifold (an edge is shared by > 2 triangles)")
    return np.column_stack([starts[a], ends[a], opp[a], opp[b]])


def _angles_and_weights(x: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    x0, x1, x2, x3 = (x[h[:, i]] for i in range(4))
    e = x1 - x0
    na = np.cross(x1 - x0, x2 - x0)
    nb_ = np.cross(x0 - x1, x3 - x1)
    elen = np.linalg.norm(e, axis=1)
    sin = np.einsum("ij,ij->i", np.cross(na, nb_), e) / elen
    cos = np.einsum("ij,ij->i", na, nb_)
    area_sum = 0.5 * (np.linalg.norm(na, axis=1) + np.linalg.norm(nb_, axis=1))
    return np.arctan2(sin, cos), 3.0 * elen**2 / area_sum


def rest_state(rest: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rest dihedral angles (rad) and hinge weights |e| / h_e = 3 |e|^2 / (A1 + A2)."""
    return _angles_and_weights(rest, h)


@nb.njit(cache=True)
def _hinge_into(x, h0, h1, h2, h3, g):
    """Signed dihedral angle of hinge (x[h0], x[h1]; opposite x[h2], x[h3]); writes d theta/dx into g (12,)."""
    e0, e1, e2 = x[h1, 0] - x[h0, 0], x[h1, 1] - x[h0, 1], x[h1, 2] - x[h0, 2]
    a0, a1, a2 = x[h2, 0] - x[h0, 0], x[h2, 1] - x[h0, 1], x[h2, 2] - x[h0, 2]
    b0, b1, b2 = x[h3, 0] - x[h1, 0], x[h3, 1] - x[h1, 1], x[h3, 2] - x[h1, 2]
    # na = e x a ; nb = (-e) x b
    na0, na1, na2 = e1 * a2 - e2 * a1, e2 * a0 - e0 * a2, e0 * a1 - e1 * a0
    nb0, nb1, nb2 = -(e1 * b2 - e2 * b1), -(e2 * b0 - e0 * b2), -(e0 * b1 - e1 * b0)
    elen = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    na2s = na0 * na0 + na1 * na1 + na2 * na2
    nb2s = nb0 * nb0 + nb1 * nb1 + nb2 * nb2
    cx0, cx1, cx2 = na1 * nb2 - na2 * nb1, na2 * nb0 - na0 * nb2, na0 * nb1 - na1 * nb0
    sin = (cx0 * e0 + cx1 * e1 + cx2 * e2) / elen
    cos = na0 * nb0 + na1 * nb1 + na2 * nb2
    theta = np.arctan2(sin, cos)
    fa = -elen / na2s
    fb = -elen / nb2s
    u0, u1, u2 = e0 / elen, e1 / elen, e2 / elen
    # projections of the opposite vertices on the edge, relative to its length
    pa0 = ((x[h2, 0] - x[h1, 0]) * u0 + (x[h2, 1] - x[h1, 1]) * u1 + (x[h2, 2] - x[h1, 2]) * u2) / elen
    pa1 = -(a0 * u0 + a1 * u1 + a2 * u2) / elen
    pb0 = (b0 * u0 + b1 * u1 + b2 * u2) / elen
    pb1 = ((x[h0, 0] - x[h3, 0]) * u0 + (x[h0, 1] - x[h3, 1]) * u1 + (x[h0, 2] - x[h3, 2]) * u2) / elen
    ga = (fa * na0, fa * na1, fa * na2)
    gb = (fb * nb0, fb * nb1, fb * nb2)
    for r in range(3):
        g[r] = pa0 * ga[r] + pb0 * gb[r]
        g[3 + r] = pa1 * ga[r] + pb1 * gb[r]
        g[6 + r] = ga[r]
        g[9 + r] = gb[r]
    return theta


@nb.njit(cache=True, parallel=True)
def bending_derivatives(x, h, theta_rest, weight, k, want_hess):
    """Energy (J), per-hinge gradients (H, 12) and Gauss-Newton Hessians (H, 12, 12)."""
    n = h.shape[0]
    grads = np.empty((n, 12))
    hess = np.empty((n, 12, 12)) if want_hess else np.empty((0, 12, 12))
    energies = np.empty(n)
    for i in nb.prange(n):
        g = np.empty(12)
        theta = _hinge_into(x, h[i, 0], h[i, 1], h[i, 2], h[i, 3], g)
        d = theta - theta_rest[i]
        # keep the angle difference in (-pi, pi]
        if d > np.pi:
            d -= 2.0 * np.pi
        elif d < -np.pi:
            d += 2.0 * np.pi
        c = k * weight[i]
        energies[i] = c * d * d
        gi = grads[i]
        for a in range(12):
            gi[a] = 2.0 * c * d * g[a]
        if want_hess:
            hi = hess[i]
            for a in range(12):
                ca = 2.0 * c * g[a]
                for b in range(12):
                    hi[a, b] = ca * g[b]
    return energies.sum(), grads, hess


def dihedral_angles(x: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Signed dihedral angles (rad) of hinges h at positions x."""
    return _angles_and_weights(x, h)[0]


@nb.njit(cache=True, parallel=True)
def bending_energy(x, h, theta_rest, weight, k):
    """Total bending energy (J)."""
    n = h.shape[0]
    energies = np.empty(n)
    for i in nb.prange(n):
        g = np.empty(12)
        d = _hinge_into(x, h[i, 0], h[i, 1], h[i, 2], h[i, 3], g) - theta_rest[i]
        if d > np.pi:
            d -= 2.0 * np.pi
        elif d < -np.pi:
            d += 2.0 * np.pi
        energies[i] = k * weight[i] * d * d
    return energies.sum()
