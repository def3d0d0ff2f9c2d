"""Fold targets and the fold loss (docs/method.md section 7).

Frame: table frame, metres. The target of a fold mirrors the vertices on the grippers'
side across the vertical plane through the fold line and raises them by
layer_offset_factor x thickness. Applying `fold_target` to the previous stage's target
gives the composed target of a fold sequence.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from .arrays import finite_array
from .folding import FoldSpec


def _vertices(v: np.ndarray, what: str = "vertices") -> np.ndarray:
    return finite_array(v, what, (-1, 3))


def folded_mask(vertices: np.ndarray, spec: FoldSpec) -> np.ndarray:
    """(N,) bool: vertices strictly on the grippers' side of the fold line (they fold)."""
    return spec.side_of_line(_vertices(vertices)) > 0.0


def mirror_across_line(points: np.ndarray, spec: FoldSpec) -> np.ndarray:
    """Points (N, 3) reflected across the vertical plane through the fold line (z kept)."""
    p = _vertices(points, "points")
    return p - 2.0 * spec.side_of_line(p)[:, None] * spec.normal


def composed_target(flat: np.ndarray, specs: Sequence[FoldSpec], thickness: float) -> np.ndarray:
    """Target (N, 3) m after the folds `specs`, in order, of the flat vertices (N, 3)."""
    out = _vertices(flat).copy()
    for spec in specs:
        out = fold_target(out, spec, thickness)
    return out


def fold_target(vertices: np.ndarray, spec: FoldSpec, thickness: float) -> np.ndarray:
    """Target (N, 3) m: folded vertices mirrored across the fold line and raised by
    spec.layer_offset_factor * thickness (m); the others unchanged."""
    if not (math.isfinite(thickness) and thickness >= 0.0):
        raise ValueError(f"thickness must be >= 0 m, got {thickness}")
    v = _vertices(vertices)
    mask = folded_mask(v, spec)
    out = v.copy()
    out[mask] = mirror_across_line(v[mask], spec)
    out[mask, 2] += spec.layer_offset_factor * thickness
    return out


def mean_vertex_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Mean Euclidean distance (m) between same-index vertices of a and b (N, 3)."""
    va, vb = _vertices(a, "first vertex array"), _vertices(b, "second vertex array")
    if va.shape != vb.shape:
        raise ValueError(f"vertex arrays differ in shape: {va.shape} vs {vb.shape}")
    if len(va) == 0:
        raise ValueError("vertex arrays are empty")
    return float(np.mean(np.linalg.norm(va - vb, axis=1)))


def distance_past_target(vertices: np.ndarray, start: np.ndarray, target: np.ndarray) -> float:
    """Mean distance (m) that the folded vertices (those whose target differs from their start)
    lie beyond their targets along their horizontal fold motion; negative: short of them.
    A fast fold's sleeve lands past its target (docs/simulator.md, "Fast folds")."""
    x, s, t = _vertices(vertices), _vertices(start, "start vertices"), _vertices(target, "target vertices")
    if not x.shape == s.shape == t.shape:
        raise ValueError(f"vertex arrays differ in shape: {x.shape}, {s.shape}, {t.shape}")
    way = t[:, :2] - s[:, :2]
    length = np.linalg.norm(way, axis=1)
    moved = length > 1e-9
    if not moved.any():
        raise ValueError("no vertex is folded: the target equals the start")
    way = way[moved] / length[moved, None]
    return float(np.mean(np.sum((x[moved, :2] - t[moved, :2]) * way, axis=1)))
