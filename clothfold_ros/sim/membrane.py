"""Isotropic compressible neo-Hookean membrane on triangles (first fundamental form).

W(F) = mu/2 (tr(F^T F) - 2) - mu ln J + lam/2 (ln J)^2, J = sqrt(det(F^T F)), with F the
3x2 deformation gradient of a triangle; element energy = rest area x thickness x W.
Hessians are projected to PSD per element (projected Newton). Units: Pa, m, J.
"""
from __future__ import annotations

import numba as nb
import numpy as np


def rest_shape(rest: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-triangle shape matrix B (M, 3, 2) with F = X^T B, and rest areas (M,) in m^2."""
    x0, x1, x2 = (rest[triangles[:, i]] for i in range(3))
    e1, e2 = x1 - x0, x2 - x0
    n = np.cross(e1, e2)
    area2 = np.linalg.norm(n, axis=1)
    if np.any(area2 <= 1e-14):
        raise ValueError("mesh has degenerate (zero-area) triangles")
    # Orthonormal frame in each triangle's plane.
    t1 = e1 / np.linalg.norm(e1, axis=1)[:, None]
    t2 = np.cross(n / area2[:, None], t1)
    dm = np.empty((len(triangles), 2, 2))
    dm[:, 0, 0] = np.einsum("ij,ij->i", e1, t1)
    dm[:, 1, 0] = np.einsum("ij,ij->i", e1, t2)
    dm[:, 0, 1] = np.einsum("ij,ij->i", e2, t1)
    dm[:, 1, 1] = np.einsum("ij,ij->i", e2, t2)
    dm_inv = np.linalg.inv(dm)
    sel = np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]])
    return np.einsum("ab,mbc->mac", sel, dm_inv), 0.5 * area2


@nb.njit(cache=True)
def _element(x: np.ndarray, b: np.ndarray, vol: float, lam: float, mu: float, want_hess: bool):
    # F (3x2) = sum_a x_a (outer) B[a]
    f = np.zeros((3, 2))
    for a in range(3):
        for r in range(3):
            for j in range(2):
                f[r, j] += x[a, r] * b[a, j]
    c = f.T @ f
    det = c[0, 0] * c[1, 1] - c[0, 1] * c[1, 0]
    if det <= 0.0:
        return np.inf, np.zeros(9), np.zeros((9, 9))
    lnj = 0.5 * np.log(det)
    energy = vol * (0.5 * mu * (c[0, 0] + c[1, 1] - 2.0) - mu * lnj + 0.5 * lam * lnj * lnj)
    cinv = np.empty((2, 2))
    cinv[0, 0] = c[1, 1] / det
    cinv[1, 1] = c[0, 0] / det
    cinv[0, 1] = -c[0, 1] / det
    cinv[1, 0] = -c[1, 0] / det
    g = f @ cinv  # d lnJ / dF
    s = lam * lnj - mu
    p = mu * f + s * g
    grad = np.zeros(9)
    for a in range(3):
        for r in range(3):
            acc = 0.0
            for j in range(2):
                acc += p[r, j] * b[a, j]
            grad[3 * a + r] = vol * acc
    hess = np.zeros((9, 9))
    if not want_hess:
        return energy, grad, hess
    # d2W/dF2 as a 6x6 matrix over F entries (r, j) -> 2 r + j.
    h6 = np.zeros((6, 6))
    fc = f @ cinv
    for k in range(3):
        for l in range(2):
            col = 2 * k + l
            # dC for dF = e_k e_l^T: dC[a, b] = d_al F[k, b] + F[k, a] d_bl
            dc = np.zeros((2, 2))
            for a2 in range(2):
                for b2 in range(2):
                    v = 0.0
                    if a2 == l:
                        v += f[k, b2]
                    if b2 == l:
                        v += f[k, a2]
                    dc[a2, b2] = v
            dg = -(fc @ dc @ cinv)
            for j in range(2):
                dg[k, j] += cinv[l, j]
            for r in range(3):
                for j in range(2):
                    h6[2 * r + j, col] = s * dg[r, j] + lam * g[r, j] * g[k, l]
            h6[col, col] += mu
    h6 = 0.5 * (h6 + h6.T)
    w, v = np.linalg.eigh(h6)
    for i in range(6):
        if w[i] < 0.0:
            w[i] = 0.0
    h6 = (v * w) @ v.T
    for a in range(3):
        for r in range(3):
            for bb in range(3):
                for t in range(3):
                    acc = 0.0
                    for j in range(2):
                        for l in range(2):
                            acc += h6[2 * r + j, 2 * t + l] * b[a, j] * b[bb, l]
                    hess[3 * a + r, 3 * bb + t] = vol * acc
    return energy, grad, hess


@nb.njit(cache=True)
def membrane_energy(x, triangles, b, vol, lam, mu):
    """Total membrane energy (J)."""
    e = 0.0
    for m in range(triangles.shape[0]):
        xe = np.empty((3, 3))
        for a in range(3):
            xe[a] = x[triangles[m, a]]
        en, _, _ = _element(xe, b[m], vol[m], lam, mu, False)
        e += en
    return e


@nb.njit(cache=True)
def membrane_derivatives(x, triangles, b, vol, lam, mu):
    """Energy (J), per-element gradients (M, 9) and PSD-projected Hessians (M, 9, 9)."""
    n = triangles.shape[0]
    grads = np.empty((n, 9))
    hessians = np.empty((n, 9, 9))
    e = 0.0
    for m in range(n):
        xe = np.empty((3, 3))
        for a in range(3):
            xe[a] = x[triangles[m, a]]
        en, g, h = _element(xe, b[m], vol[m], lam, mu, True)
        e += en
        grads[m] = g
        hessians[m] = h
    return e, grads, hessians
