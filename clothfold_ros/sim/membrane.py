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


@nb.njit(cache=True, fastmath=False)
def _element(x: np.ndarray, b: np.ndarray, vol: float, lam: float, mu: float, want_hess: bool):
    # F (3x2) = sum_a x_a (outer) B[a]; small products written out (no BLAS calls).
    f = np.zeros((3, 2))
    for a in range(3):
        for r in range(3):
            for j in range(2):
                f[r, j] += x[a, r] * b[a, j]
    c00 = f[0, 0] * f[0, 0] + f[1, 0] * f[1, 0] + f[2, 0] * f[2, 0]
    c11 = f[0, 1] * f[0, 1] + f[1, 1] * f[1, 1] + f[2, 1] * f[2, 1]
    c01 = f[0, 0] * f[0, 1] + f[1, 0] * f[1, 1] + f[2, 0] * f[2, 1]
    det = c00 * c11 - c01 * c01
    grad = np.zeros(9)
    hess = np.zeros((9, 9))
    if det <= 0.0:
        return np.inf, grad, hess
    lnj = 0.5 * np.log(det)
    energy = vol * (0.5 * mu * (c00 + c11 - 2.0) - mu * lnj + 0.5 * lam * lnj * lnj)
    ci = np.empty((2, 2))
    ci[0, 0] = c11 / det
    ci[1, 1] = c00 / det
    ci[0, 1] = -c01 / det
    ci[1, 0] = -c01 / det
    g = np.empty((3, 2))  # G = F C^-1 = d lnJ / dF
    for r in range(3):
        for j in range(2):
            g[r, j] = f[r, 0] * ci[0, j] + f[r, 1] * ci[1, j]
    s = lam * lnj - mu
    for a in range(3):
        for r in range(3):
            acc = 0.0
            for j in range(2):
                acc += (mu * f[r, j] + s * g[r, j]) * b[a, j]
            grad[3 * a + r] = vol * acc
    if not want_hess:
        return energy, grad, hess
    # d2W/dF2 (6x6 over F entries (r, j) -> 2 r + j):
    # mu I + lam vec(G) vec(G)^T + s dG/dF, dG = dF C^-1 - G (dF^T F + F^T dF) C^-1.
    h6 = np.empty((6, 6))
    for k in range(3):
        for l in range(2):
            col = 2 * k + l
            # dC for dF = e_k e_l^T: dC[p, q] = d_pl F[k, q] + F[k, p] d_ql
            dc = np.zeros((2, 2))
            for q in range(2):
                dc[l, q] += f[k, q]
                dc[q, l] += f[k, q]
            # m = dC C^-1 (2x2)
            m00 = dc[0, 0] * ci[0, 0] + dc[0, 1] * ci[1, 0]
            m01 = dc[0, 0] * ci[0, 1] + dc[0, 1] * ci[1, 1]
            m10 = dc[1, 0] * ci[0, 0] + dc[1, 1] * ci[1, 0]
            m11 = dc[1, 0] * ci[0, 1] + dc[1, 1] * ci[1, 1]
            for r in range(3):
                dg0 = -(g[r, 0] * m00 + g[r, 1] * m10)
                dg1 = -(g[r, 0] * m01 + g[r, 1] * m11)
                if r == k:
                    dg0 += ci[l, 0]
                    dg1 += ci[l, 1]
                h6[2 * r, col] = s * dg0 + lam * g[r, 0] * g[k, l]
                h6[2 * r + 1, col] = s * dg1 + lam * g[r, 1] * g[k, l]
            h6[col, col] += mu
    for i in range(6):
        for j in range(i + 1, 6):
            avg = 0.5 * (h6[i, j] + h6[j, i])
            h6[i, j] = avg
            h6[j, i] = avg
    w, v = np.linalg.eigh(h6)
    if w[0] < 0.0:  # clamp negative eigenvalues (projected Newton)
        for i in range(6):
            if w[i] < 0.0:
                w[i] = 0.0
        for i in range(6):
            for j in range(i, 6):
                acc = 0.0
                for q in range(6):
                    acc += v[i, q] * w[q] * v[j, q]
                h6[i, j] = acc
                h6[j, i] = acc
    # K[(a, r), (c, t)] = vol sum_{j, l} H6[(r, j), (t, l)] B[a, j] B[c, l]
    for r in range(3):
        for t in range(3):
            h00 = h6[2 * r, 2 * t]
            h01 = h6[2 * r, 2 * t + 1]
            h10 = h6[2 * r + 1, 2 * t]
            h11 = h6[2 * r + 1, 2 * t + 1]
            for a in range(3):
                ba0 = b[a, 0]
                ba1 = b[a, 1]
                for cc in range(3):
                    bc0 = b[cc, 0]
                    bc1 = b[cc, 1]
                    hess[3 * a + r, 3 * cc + t] = vol * (
                        ba0 * (h00 * bc0 + h01 * bc1) + ba1 * (h10 * bc0 + h11 * bc1)
                    )
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


@nb.njit(cache=True, parallel=True)
def membrane_derivatives(x, triangles, b, vol, lam, mu):
    """Energy (J), per-element gradients (M, 9) and PSD-projected Hessians (M, 9, 9)."""
    n = triangles.shape[0]
    grads = np.empty((n, 9))
    hessians = np.empty((n, 9, 9))
    energies = np.empty(n)
    for m in nb.prange(n):
        xe = np.empty((3, 3))
        for a in range(3):
            xe[a] = x[triangles[m, a]]
        en, g, h = _element(xe, b[m], vol[m], lam, mu, True)
        energies[m] = en
        grads[m] = g
        hessians[m] = h
    return energies.sum(), grads, hessians
