"""Contact of the cloth with the table top (the plane z = 0) in closed form.

The same potentials ipctk evaluates for a vertex-plane pair, without building a sparse
matrix per call: with s = z^2 - xi^2 and s_hat = (xi + dhat)^2 - xi^2 the barrier is
kappa * b(s) with IPC's log barrier b(s) = -(s - s_hat)^2 ln(s / s_hat) for s < s_hat, and
lagged smoothed Coulomb friction mu * lambda * f0(|u_xy|) with the normal force lambda
fixed at the start of the step and f0 IPC's C1 smoothing over eps (m, a displacement).
Both act only within a vertex's own 3x3 block: the barrier on zz, friction on the xy
block, so the table never adds fill to the Newton matrix. Units: m, J (the incremental
potential's scaling), table frame (z up).
"""
from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def _barrier(z, xi, dhat, kappa, want):
    """Energy, dE/dz (N,) and the clamped d2E/dz2 (N,) (want: 0 energy, 1 + gradient, 2 + Hessian)."""
    n = z.shape[0]
    sh = (xi + dhat) ** 2 - xi * xi
    e = 0.0
    g = np.zeros(n)
    h = np.zeros(n)
    for i in range(n):
        s = z[i] * z[i] - xi * xi
        if s >= sh:
            continue
        if s <= 0.0:
            return np.inf, g, h
        r = s - sh
        ln = np.log(s / sh)
        e += -r * r * ln
        if want >= 1:
            b1 = -2.0 * r * ln - r * r / s
            g[i] = kappa * b1 * 2.0 * z[i]
            if want >= 2:
                b2 = -2.0 * ln - 4.0 * r / s + r * r / (s * s)
                h[i] = max(0.0, kappa * (b2 * 4.0 * z[i] * z[i] + 2.0 * b1))
    return kappa * e, g, h


@nb.njit(cache=True)
def _friction(u, ids, lam, mu, eps, want):
    """Energy, gradient (N, 3) and xy blocks (k, 3: xx, xy, yy) of the lagged table friction."""
    g = np.zeros(u.shape)
    hb = np.zeros((ids.shape[0], 3))
    e = 0.0
    for k in range(ids.shape[0]):
        i = ids[k]
        c = mu * lam[k]
        ux, uy = u[i, 0], u[i, 1]
        x = np.sqrt(ux * ux + uy * uy)
        if x >= eps:
            e += c * x
        else:
            e += c * (x * x / eps - x * x * x / (3.0 * eps * eps) + eps / 3.0)
        if want == 0:
            continue
        f1_over_x = 1.0 / x if x >= eps else 2.0 / eps - x / (eps * eps)
        g[i, 0] = c * f1_over_x * ux
        g[i, 1] = c * f1_over_x * uy
        if want == 1:
            continue
        # c [f1/x I + (f1' - f1/x) u u^T / x^2]: f1' = 0 sliding, 2/eps - 2x/eps^2 sticking (PSD both)
        if x >= eps:
            w = -1.0 / (x * x * x)
        else:
            w = -1.0 / (eps * eps * x) if x > 0.0 else 0.0
        hb[k, 0] = c * (f1_over_x + w * ux * ux)
        hb[k, 1] = c * w * ux * uy
        hb[k, 2] = c * (f1_over_x + w * uy * uy)
    return e, g, hb


class TableContact:
    """Barrier and lagged friction between the cloth's vertices and the table top."""

    def __init__(self, xi: float, dhat: float, friction: float, eps: float) -> None:
        self.xi, self.dhat = float(xi), float(dhat)
        self.friction_coefficient = float(friction)
        self.eps = float(eps)  # m: friction smoothing displacement (eps_v x dt)
        self._ids = np.zeros(0, dtype=np.int64)  # vertices in contact at the start of the step
        self._lam = np.zeros(0)  # their lagged normal forces

    def active(self, x: np.ndarray) -> np.ndarray:
        """Vertices within the barrier's range of the table (z < xi + dhat)."""
        return np.flatnonzero(x[:, 2] < self.xi + self.dhat)

    def min_distance(self, x: np.ndarray) -> float:
        """Smallest height (m) of a vertex within the barrier's range; inf when none."""
        z = x[:, 2]
        near = z < self.xi + self.dhat
        return float(z[near].min()) if near.any() else np.inf

    def lag_friction(self, x: np.ndarray, kappa: float) -> None:
        """Fix the normal forces kappa |dB/dz| of the vertices in contact at x."""
        ids = self.active(x)
        _, g, _ = _barrier(np.ascontiguousarray(x[ids, 2]), self.xi, self.dhat, kappa, 1)
        keep = g != 0.0
        self._ids, self._lam = ids[keep], np.abs(g[keep])
        if self.friction_coefficient == 0.0:
            self._ids, self._lam = self._ids[:0], self._lam[:0]

    def energy(self, x: np.ndarray, u: np.ndarray, kappa: float) -> float:
        e, _, _ = _barrier(np.ascontiguousarray(x[:, 2]), self.xi, self.dhat, kappa, 0)
        if len(self._ids):
            e += _friction(np.ascontiguousarray(u), self._ids, self._lam, self.friction_coefficient, self.eps, 0)[0]
        return float(e)

    def gradient(self, x: np.ndarray, u: np.ndarray, kappa: float) -> np.ndarray:
        """Gradient (3N,) of barrier and friction."""
        _, gz, _ = _barrier(np.ascontiguousarray(x[:, 2]), self.xi, self.dhat, kappa, 1)
        g = np.zeros(x.shape)
        g[:, 2] = gz
        if len(self._ids):
            g += _friction(np.ascontiguousarray(u), self._ids, self._lam, self.friction_coefficient, self.eps, 1)[1]
        return g.ravel()

    def hessian_blocks(self, x: np.ndarray, u: np.ndarray, kappa: float) -> tuple[np.ndarray, np.ndarray]:
        """(vertex ids (k,), upper entries of their 3x3 blocks (k, 6): xx xy xz yy yz zz), PSD."""
        _, _, hz = _barrier(np.ascontiguousarray(x[:, 2]), self.xi, self.dhat, kappa, 2)
        zi = np.flatnonzero(hz)
        ids = np.union1d(zi, self._ids)
        blocks = np.zeros((len(ids), 6))
        blocks[np.searchsorted(ids, zi), 5] = hz[zi]
        if len(self._ids):
            _, _, hb = _friction(np.ascontiguousarray(u), self._ids, self._lam, self.friction_coefficient, self.eps, 2)
            at = np.searchsorted(ids, self._ids)
            blocks[at, 0], blocks[at, 1], blocks[at, 3] = hb[:, 0], hb[:, 1], hb[:, 2]
        return ids, blocks

    def count(self, x: np.ndarray) -> int:
        return int(len(self.active(x)))
