"""Subspace Newton directions: the Newton system restricted to the vertices still moving.

Late in a step's Newton solve most of the shirt has converged (on the 3K default fold,
from the sixth iteration of a step on, 10-18 % of the vertices carry a step above a tenth
of the Newton tolerance) while the factorization still covers every vertex. A subspace
iteration solves H_AA p_A = -g_A on the active vertices A and leaves the others where
they are: H_AA is a principal block of a positive definite matrix, so p is a descent
direction, and it is the exact Newton step of the potential with the other vertices
held. The simulator confirms convergence with a full direction (simulator.py).

The pattern is the simulator's upper 3x3 block triangle (`pattern.HessianPattern`:
sorted block rows, blocks row-major); the subsystem keeps the same layout.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np


@dataclass(frozen=True, eq=False)
class Subsystem:
    """The blocks of an upper block-triangular pattern among the vertices `active`."""

    active: np.ndarray  # (N,) bool: vertices in the subsystem
    vertices: np.ndarray  # (n,) their ids, ascending (subsystem vertex k is vertex vertices[k])
    blocks: np.ndarray  # (nnz_sub,) slots of the pattern's blocks kept, in subsystem order
    indptr: np.ndarray  # (n + 1,) int32 block-row pointers of the subsystem
    indices: np.ndarray  # (nnz_sub,) int32 block columns of the subsystem

    def values(self, data: np.ndarray) -> np.ndarray:
        """The subsystem's block values from the full pattern's values (9 per block)."""
        return data.reshape(-1, 9)[self.blocks].ravel()

    @cached_property
    def dofs(self) -> np.ndarray:
        """Degrees of freedom (3 per vertex, vertex-major) of the subsystem in the full vector."""
        return (3 * self.vertices[:, None] + np.arange(3)).ravel()

    @cached_property
    def diag_slots(self) -> np.ndarray:
        """Value index of each subsystem DOF's diagonal entry (a row's first block is its diagonal)."""
        return (9 * self.indptr[:-1, None] + np.array([0, 4, 8])).ravel()


def subsystem(block_rows: np.ndarray, indices: np.ndarray, active: np.ndarray) -> Subsystem:
    """The principal subsystem of the pattern (block row and column of every block) on `active`."""
    keep = np.flatnonzero(active[block_rows] & active[indices])
    renumber = np.cumsum(active) - 1  # new id of each active vertex
    rows = renumber[block_rows[keep]]
    vertices = np.flatnonzero(active)
    indptr = np.searchsorted(rows, np.arange(len(vertices) + 1)).astype(np.int32)
    return Subsystem(active.copy(), vertices, keep, indptr, renumber[indices[keep]].astype(np.int32))


def active_vertices(step: np.ndarray, threshold: float, block_rows: np.ndarray, indices: np.ndarray,
                    rings: int = 1) -> np.ndarray:
    """Vertices whose step (N, 3) is longer than `threshold` (m), grown by `rings` rings of
    the pattern's graph (mesh neighbours, hinges and contact partners alike)."""
    active = np.sum(step * step, axis=1) > threshold * threshold
    for _ in range(rings):
        grown = active.copy()
        grown[indices[active[block_rows]]] = True
        grown[block_rows[active[indices]]] = True
        active = grown
    return active


@dataclass(frozen=True, eq=False)
class ElementSubset:
    """The elements touching a subsystem's vertices: indices into the triangles and hinges,
    and their rows of the pattern's element block slots (`HessianPattern.block_slots`)."""

    triangles: np.ndarray  # (m,) triangle indices
    hinges: np.ndarray  # (k,) hinge indices
    block_slots: list[np.ndarray]  # [triangle slots (m, ...), hinge slots (k, ...)]


def element_subset(active: np.ndarray, triangles: np.ndarray, hinges: np.ndarray,
                   block_slots: list[np.ndarray]) -> ElementSubset:
    """Triangles (M, 3) and hinges (H, 4) with at least one vertex in `active` (N,) bool."""
    t = np.flatnonzero(active[triangles].any(axis=1))
    k = np.flatnonzero(active[hinges].any(axis=1))
    return ElementSubset(t, k, [block_slots[0][t], block_slots[1][k]])
