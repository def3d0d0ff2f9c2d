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
def _hinge(x0, x1, x2, x3):
    e = x1 - x0
    na = np.cross(x1 - x0, x2 - x0)
    nb_ = np.cross(x0 - x1, x3 - x1)
    elen = np.sqrt(e @ e)
    na2 = na @ na
    nb2 = nb_ @ nb_
    sin = (np.cross(na, nb_) @ e) / elen
    cos = na @ nb_
    theta = np.arctan2(sin, cos)
    g = np.empty(12)
    g2 = -elen / na2 * na
    g3 = -elen / nb2 * nb_
    ehat = e / elen
    a0 = ((x2 - x1) @ ehat) / elen
    a1 = ((x0 - x2) @ ehat) / elen
    b0 = ((x3 - x1) @ ehat) / elen
    b1 = ((x0 - x3) @ ehat) / elen
    g0 = a0 * g2 + b0 * g3
    g1 = a1 * g2 + b1 * g3
    g[0:3] = g0
    g[3:6] = g1
    g[6:9] = g2
    g[9:12] = g3
    return theta, g


@nb.njit(cache=True, parallel=True)
def bending_derivatives(x, h, theta_rest, weight, k, want_hess):
    """Energy (J), per-hinge gradients (H, 12) and Gauss-Newton Hessians (H, 12, 12)."""
    n = h.shape[0]
    grads = np.empty((n, 12))
    hess = np.empty((n, 12, 12)) if want_hess else np.empty((0, 12, 12))
    energies = np.empty(n)
    for i in nb.prange(n):
        theta, g = _hinge(x[h[i, 0]], x[h[i, 1]], x[h[i, 2]], x[h[i, 3]])
        d = theta - theta_rest[i]
        # keep the angle difference in (-pi, pi]
        if d > np.pi:
            d -= 2.0 * np.pi
        elif d < -np.pi:
            d += 2.0 * np.pi
        c = k * weight[i]
        energies[i] = c * d * d
        for a in range(12):
            grads[i, a] = 2.0 * c * d * g[a]
        if want_hess:
            for a in range(12):
                for b in range(12):
                    hess[i, a, b] = 2.0 * c * g[a] * g[b]
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
        x0, x1, x2, x3 = x[h[i, 0]], x[h[i, 1]], x[h[i, 2]], x[h[i, 3]]
        e = x1 - x0
        na = np.cross(e, x2 - x0)
        nb_ = np.cross(x0 - x1, x3 - x1)
        elen = np.sqrt(e @ e)
        theta = np.arctan2((np.cross(na, nb_) @ e) / elen, na @ nb_)
        d = theta - theta_rest[i]
        if d > np.pi:
            d -= 2.0 * np.pi
        elif d < -np.pi:
            d += 2.0 * np.pi
        energies[i] = k * weight[i] * d * d
    return energies.sum()
