"""Isotropic compressible neo-Hookean membrane on triangles (first fundamental form).

W(F) = mu/2 (tr(F^T F) - 2) - mu ln J + lam/2 (ln J)^2, J = sqrt(det(F^T F)), with F the
3x2 deformation gradient of a triangle; element energy = rest area x thickness x W.
Hessians are made PSD per element (projected Newton) from the closed-form eigensystem
of the 6x6 Hessian in F: negative eigenvalues are clamped to zero (PROJECT_CLAMP) or
replaced by their absolute value (PROJECT_ABS). Units: Pa, m, J.
"""
from __future__ import annotations

import numba as nb
import numpy as np

PROJECT_NONE = 0  # exact Hessian (tests)
PROJECT_CLAMP = 1
PROJECT_ABS = 2


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


@nb.njit(cache=True, inline="always")
def _sym2_eig(a, b, d):
    """Eigen-decomposition of the symmetric 2x2 [[a, b], [b, d]]: (l1 >= l2, (c, s) of l1's vector)."""
    half = 0.5 * (a - d)
    r = np.sqrt(half * half + b * b)
    l1 = 0.5 * (a + d) + r
    l2 = 0.5 * (a + d) - r
    if r <= 1e-12 * (abs(a) + abs(d)):  # (nearly) a multiple of the identity: any basis
        return l1, l2, 1.0, 0.0
    if half >= 0.0:  # (l1 - d, b) is the better conditioned vector
        c, s = l1 - d, b
    else:
        c, s = b, l1 - a
    n = np.sqrt(c * c + s * s)
    return l1, l2, c / n, s / n


@nb.njit(cache=True)
def _element(x, b, vol, lam, mu, project, grad, hess, want_hess=True):
    """Energy (J) of one triangle; writes its gradient (9,) and projected Hessian (9, 9).

    The 6x6 Hessian in F has a closed-form eigensystem for an isotropic energy of a 3x2
    F = U diag(s1, s2) V^T (u3 = u1 x u2 the normal): two scaling modes (the 2x2 Hessian
    in (s1, s2)), twist (u1 v2^T - u2 v1^T) with eigenvalue mu + t/(s1 s2), flip
    (u1 v2^T + u2 v1^T) with mu - t/(s1 s2), and the two out-of-plane modes u3 v_i^T
    with mu + t/s_i^2, where t = lam ln J - mu. No numerical eigen-solver is needed.
    """
    f = np.zeros((3, 2))
    for a in range(3):
        for r in range(3):
            f[r, 0] += x[a, r] * b[a, 0]
            f[r, 1] += x[a, r] * b[a, 1]
    c00 = f[0, 0] * f[0, 0] + f[1, 0] * f[1, 0] + f[2, 0] * f[2, 0]
    c11 = f[0, 1] * f[0, 1] + f[1, 1] * f[1, 1] + f[2, 1] * f[2, 1]
    c01 = f[0, 0] * f[0, 1] + f[1, 0] * f[1, 1] + f[2, 0] * f[2, 1]
    det = c00 * c11 - c01 * c01
    grad[:] = 0.0
    hess[:, :] = 0.0
    if det <= 0.0:
        return np.inf
    lnj = 0.5 * np.log(det)
    energy = vol * (0.5 * mu * (c00 + c11 - 2.0) - mu * lnj + 0.5 * lam * lnj * lnj)
    t = lam * lnj - mu
    # dW/dF = mu F + t F C^-1
    i00, i11, i01 = c11 / det, c00 / det, -c01 / det
    p = np.empty((3, 2))
    for r in range(3):
        p[r, 0] = mu * f[r, 0] + t * (f[r, 0] * i00 + f[r, 1] * i01)
        p[r, 1] = mu * f[r, 1] + t * (f[r, 0] * i01 + f[r, 1] * i11)
    for a in range(3):
        for r in range(3):
            grad[3 * a + r] = vol * (p[r, 0] * b[a, 0] + p[r, 1] * b[a, 1])
    if not want_hess:
        return energy
    # Thin SVD of F from C = V diag(s^2) V^T.
    e1, e2, vc, vs = _sym2_eig(c00, c01, c11)
    s1 = np.sqrt(e1)
    s2 = np.sqrt(max(e2, 0.0))
    if s2 <= 0.0:
        return energy
    v1 = (vc, vs)
    v2 = (-vs, vc)
    u = np.empty((3, 3))
    for r in range(3):
        u[r, 0] = (f[r, 0] * v1[0] + f[r, 1] * v1[1]) / s1
        u[r, 1] = (f[r, 0] * v2[0] + f[r, 1] * v2[1]) / s2
    u[0, 2] = u[1, 0] * u[2, 1] - u[2, 0] * u[1, 1]
    u[1, 2] = u[2, 0] * u[0, 1] - u[0, 0] * u[2, 1]
    u[2, 2] = u[0, 0] * u[1, 1] - u[1, 0] * u[0, 1]
    # Eigenvalues and eigen-matrices Q_k (3x2) = sum of u_i v_j^T terms.
    a11 = mu + (lam - t) / e1
    a22 = mu + (lam - t) / e2
    a12 = lam / (s1 * s2)
    l1, l2, wc, ws = _sym2_eig(a11, a12, a22)
    vals = np.array([l1, l2, mu + t / (s1 * s2), mu - t / (s1 * s2), mu + t / e1, mu + t / e2])
    # coefficients of each mode on (u_i v_j^T): rows = modes, (i, j) pairs below
    coef = np.zeros((6, 6))  # columns: (0,0) (1,1) (0,1) (1,0) (2,0) (2,1)
    coef[0, 0], coef[0, 1] = wc, ws
    coef[1, 0], coef[1, 1] = -ws, wc
    r2 = 1.0 / np.sqrt(2.0)
    coef[2, 2], coef[2, 3] = r2, -r2
    coef[3, 2], coef[3, 3] = r2, r2
    coef[4, 4] = 1.0
    coef[5, 5] = 1.0
    ui = (0, 1, 0, 1, 2, 2)
    vj = (0, 1, 1, 0, 0, 1)
    w = np.empty(9)
    for k in range(6):
        lk = vals[k]
        if lk < 0.0:
            if project == PROJECT_ABS:
                lk = -lk
            elif project == PROJECT_CLAMP:
                continue
        # Q_k = sum_m coef[k, m] u_{ui[m]} v_{vj[m]}^T ; w = vec(B Q_k^T) over (vertex a, row r)
        q = np.zeros((3, 2))
        for m in range(6):
            cm = coef[k, m]
            if cm != 0.0:
                vv = v1 if vj[m] == 0 else v2
                for r in range(3):
                    q[r, 0] += cm * u[r, ui[m]] * vv[0]
                    q[r, 1] += cm * u[r, ui[m]] * vv[1]
        for a in range(3):
            for r in range(3):
                w[3 * a + r] = q[r, 0] * b[a, 0] + q[r, 1] * b[a, 1]
        sc = vol * lk
        for i in range(9):
            wi = sc * w[i]
            for j in range(9):
                hess[i, j] += wi * w[j]
    return energy


@nb.njit(cache=True, parallel=True)
def membrane_energy(x, triangles, b, vol, lam, mu):
    """Total membrane energy (J); inf where a triangle is inverted or degenerate."""
    n = triangles.shape[0]
    energies = np.empty(n)
    for m in nb.prange(n):
        x0, x1, x2 = x[triangles[m, 0]], x[triangles[m, 1]], x[triangles[m, 2]]
        bm = b[m]
        c00 = c11 = c01 = 0.0
        for r in range(3):
            f0 = x0[r] * bm[0, 0] + x1[r] * bm[1, 0] + x2[r] * bm[2, 0]
            f1 = x0[r] * bm[0, 1] + x1[r] * bm[1, 1] + x2[r] * bm[2, 1]
            c00 += f0 * f0
            c11 += f1 * f1
            c01 += f0 * f1
        det = c00 * c11 - c01 * c01
        if det <= 0.0:
            energies[m] = np.inf
        else:
            lnj = 0.5 * np.log(det)
            energies[m] = vol[m] * (0.5 * mu * (c00 + c11 - 2.0) - mu * lnj + 0.5 * lam * lnj * lnj)
    return energies.sum()


@nb.njit(cache=True, parallel=True)
def membrane_derivatives(x, triangles, b, vol, lam, mu, project=PROJECT_CLAMP, want_hess=True):
    """Energy (J), per-element gradients (M, 9) and PSD-projected Hessians (M, 9, 9)
    (zeros when want_hess is False)."""
    n = triangles.shape[0]
    grads = np.empty((n, 9))
    hessians = np.empty((n, 9, 9)) if want_hess else np.zeros((n, 0, 0))
    energies = np.empty(n)
    for m in nb.prange(n):
        xe = np.empty((3, 3))
        for a in range(3):
            xe[a] = x[triangles[m, a]]
        h = hessians[m] if want_hess else np.empty((9, 9))
        energies[m] = _element(xe, b[m], vol[m], lam, mu, project, grads[m], h, want_hess)
    return energies.sum(), grads, hessians
