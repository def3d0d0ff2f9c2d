"""Folded-state keypoints: the shirt's 13 keypoints as a camera looking down sees them.

Frame: table frame, metres, z up; all fold geometry is horizontal (x, y). Defined once
here and used by the cloth-state keypoints, the point-cloud estimator and the benchmark.

A flat shirt's keypoints are its material points (`Garment.keypoints`). Each fold done
(in order, as planned: `FoldSpec`s or `FoldLine`s) changes the keypoints it moves, by the
rules of its type in `folding.FOLD_KINDS` (`keeps_keypoints`, `outline_corners`):

| fold | keypoint moved by it | visible keypoint |
|---|---|---|
| sleeve | sleeve_top/bottom_<side> | the material point: where the folded cuff now lies (on top) |
| sleeve | shoulder_<side> (neck_<side>) | where the fold line cuts the outline from it toward neck_middle: the folded outline's upper corner |
| side | every other moved keypoint (bottom, armpit, shoulder, ...) | its projection onto the fold line: on the crease, e.g. the hem corner becomes the folded outline's corner a quarter of the flat hem width in |
| side | sleeve keypoints | the material point |
| middle | every keypoint | the material point (the hem now lies on top) |

For a fold whose visible crease lies inside its line (`FoldLine.crease`, fitted on real
folds), the crease constructions use the crease; the mirroring uses the line.

Each visible keypoint is a material point of the cloth (a location on the flat shirt,
`keypoint_locations`); on a mesh its position is where that cloth point is now, fitted
from nearby vertices that the folds moved the same way, so it is exact on ideally folded
states (`loss.fold_target` composed stage by stage) and follows a simulated cloth.
Material keypoints stay available as `Garment.keypoints(vertices)` for evaluation.
"""
from __future__ import annotations

import math

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..folding import FOLD_KINDS, FoldSpec, fold_type
from ..garment import KEYPOINT_NAMES, Garment

SIDE_TOL = 1e-6  # m: a point closer than this to a fold line is on it (not moved)
_IDX = {n: i for i, n in enumerate(KEYPOINT_NAMES)}


@dataclass(frozen=True)
class FoldLine:
    """A done fold in the plane: name (folding.FOLD_NAMES), a point on the line (2,) m and
    the unit normal (2,) toward the grippers' side (the side that was folded over: it is
    mirrored across the line). crease (m, >= 0): the visible fold edge lies this far from
    the line toward the unfolded side (a real fold's bulge takes up the cloth in between);
    0 for an ideal fold."""

    name: str
    point: np.ndarray
    normal: np.ndarray
    crease: float = 0.0

    def __post_init__(self) -> None:
        if self.name:  # "" for a line of no named fold (the estimator's model)
            fold_type(self.name)  # ValueError for an unknown fold
        point, normal = np.asarray(self.point, float), np.asarray(self.normal, float)
        if point.shape != (2,) or normal.shape != (2,) or not (np.isfinite(point).all() and np.isfinite(normal).all()):
            raise ValueError(f"fold line {self.name}: point and normal must be finite (2,) arrays (m, -)")
        if abs(np.linalg.norm(normal) - 1.0) > 1e-6:
            raise ValueError(f"fold line {self.name}: the normal must be a unit vector, |n| = {np.linalg.norm(normal)}")
        if not (math.isfinite(self.crease) and self.crease >= 0):
            raise ValueError(f"fold line {self.name}: crease must be >= 0 m, got {self.crease}")
        object.__setattr__(self, "point", point)
        object.__setattr__(self, "normal", normal)

    @staticmethod
    def of(fold: "FoldLine | FoldSpec") -> "FoldLine":
        if isinstance(fold, FoldLine):
            return fold
        if isinstance(fold, FoldSpec):
            return FoldLine(fold.name, np.asarray(fold.line_point[:2], float), np.asarray(fold.normal[:2], float))
        raise TypeError(f"a fold must be a FoldSpec or FoldLine, got {type(fold).__name__}")

    @property
    def kind(self) -> str:
        return fold_type(self.name)

    def side(self, xy: np.ndarray) -> np.ndarray:
        """Signed distance (m) of points (..., 2) from the line, > 0 on the folded side."""
        return (np.asarray(xy, float)[..., :2] - self.point) @ self.normal

    @property
    def crease_line(self) -> "FoldLine":
        """The visible fold edge as a line (same normal)."""
        return FoldLine(self.name, self.point - self.crease * self.normal, self.normal)


def fold_lines(folds: Sequence["FoldLine | FoldSpec"]) -> list[FoldLine]:
    return [FoldLine.of(f) for f in folds]


def apply_folds(xy: np.ndarray, folds: Sequence["FoldLine | FoldSpec"], return_moves: bool = False):
    """Ideal folding of flat points (N, 2): each fold in turn mirrors the points on its
    folded side across its line. Returns (N, 2), with return_moves also (N, K) bool: which
    fold moved which point."""
    p = np.array(xy, dtype=float)[..., :2].reshape(-1, 2)
    moves = np.zeros((len(p), len(folds)), dtype=bool)
    for k, f in enumerate(fold_lines(folds)):
        s = f.side(p)
        m = s > SIDE_TOL
        p[m] -= 2.0 * s[m, None] * f.normal
        moves[:, k] = m
    return (p, moves) if return_moves else p


def _first_crossing(path: np.ndarray, f: FoldLine) -> np.ndarray | None:
    """First point where the polyline path (P, 2), starting on the folded side, reaches the line."""
    s = f.side(path)
    for j in range(len(path) - 1):
        if s[j] > SIDE_TOL and s[j + 1] <= SIDE_TOL:
            t = s[j] / (s[j] - s[j + 1])
            return path[j] + t * (path[j + 1] - path[j])
    return None


def _untrack(q: np.ndarray, prev: list[FoldLine], outline: np.ndarray) -> np.ndarray:
    """The flat location whose ideally folded position (through `prev`) is q: of the cloth
    layers lying at q, the lowest (the one the fewest folds moved)."""
    import shapely

    if not prev:
        return q
    k = len(prev)
    choices = (np.arange(2**k)[:, None] >> np.arange(k)[None]) & 1  # (2^k, k): un-mirror fold j?
    x = np.repeat(q[None], len(choices), axis=0)
    for j in reversed(range(k)):
        f = prev[j]
        c = choices[:, j].astype(bool)
        x[c] -= 2.0 * f.side(x[c])[:, None] * f.normal
    back, moves = apply_folds(x, prev, return_moves=True)
    ok = (np.linalg.norm(back - q, axis=1) < 1e-7) & np.all(moves == choices.astype(bool), axis=1)
    ok &= shapely.intersects_xy(shapely.Polygon(outline).buffer(1e-7), x[:, 0], x[:, 1])
    if not ok.any():
        return q
    i = np.flatnonzero(ok)[np.argmin(choices[ok].sum(axis=1))]
    return x[i]


def keypoint_locations(outline: np.ndarray, folds: Sequence["FoldLine | FoldSpec"]) -> np.ndarray:
    """(13, 2) flat-shirt locations (same frame as `outline`, the flat shirt's (13, 2)
    keypoints in KEYPOINT_NAMES order) of the visible keypoints after `folds`; the table in
    the module docstring gives the rules."""
    outline = np.asarray(outline, dtype=float)[:, :2]
    if outline.shape != (len(KEYPOINT_NAMES), 2):
        raise ValueError(f"outline must have shape ({len(KEYPOINT_NAMES)}, 2), got {outline.shape}")
    lines = fold_lines(folds)
    loc = outline.copy()
    for k, f in enumerate(lines):
        kind = FOLD_KINDS[f.kind]
        if kind.keeps_keypoints:
            continue
        prev = lines[:k]
        cur = apply_folds(loc, prev)
        edge = f.crease_line
        s = edge.side(cur)
        side = f.name.split("_")[0]
        corners = {name.format(side=side): [n.format(side=side) for n in path] for name, path in kind.outline_corners}
        for i, name in enumerate(KEYPOINT_NAMES):
            if s[i] <= SIDE_TOL or name.startswith("sleeve_"):
                continue
            q = None
            if name in corners:
                path = [name, *corners[name]]
                q = _first_crossing(apply_folds(outline[[_IDX[n] for n in path]], prev), edge)
            if q is None:
                q = cur[i] - s[i] * f.normal  # projection onto the crease
            loc[i] = _untrack(q, prev, outline)
    return loc


def ideal_visible_keypoints(outline: np.ndarray, folds: Sequence["FoldLine | FoldSpec"]) -> np.ndarray:
    """(13, 2) visible keypoints of the ideally folded flat outline (13, 2)."""
    return apply_folds(keypoint_locations(outline, folds), folds)


def locate(flat_xy: np.ndarray, vertices: np.ndarray, points: np.ndarray, folds: Sequence["FoldLine | FoldSpec"],
           neighbours: int = 8) -> np.ndarray:
    """Current positions (P, 3) of flat cloth locations points (P, 2): a distance-weighted
    affine fit, flat (x, y) -> current (x, y, z), over the nearest vertices (flat positions
    flat_xy (N, 2), current vertices (N, 3)) that the folds moved like the point."""
    flat_xy = np.asarray(flat_xy, float)[:, :2]
    v = np.asarray(vertices, float)
    pts = np.asarray(points, float).reshape(-1, 2)
    _, vm = apply_folds(flat_xy, folds, return_moves=True)
    _, pm = apply_folds(pts, folds, return_moves=True)
    out = np.empty((len(pts), 3))
    for i, (p, m) in enumerate(zip(pts, pm)):
        same = np.flatnonzero(np.all(vm == m, axis=1))
        if len(same) < 3:
            same = np.arange(len(flat_xy))
        d = np.linalg.norm(flat_xy[same] - p, axis=1)
        near = same[np.argsort(d)[:neighbours]]
        dn = np.sort(d)[:neighbours]
        w = 1.0 / (dn + 1e-3)
        a = np.column_stack([flat_xy[near] - p, np.ones(len(near))]) * w[:, None]
        coef, *_ = np.linalg.lstsq(a, v[near] * w[:, None], rcond=None)
        out[i] = coef[2]  # the affine map evaluated at p (local coordinates 0)
    return out


def visible_keypoints(garment: Garment, vertices: np.ndarray | None = None,
                      folds: Sequence["FoldLine | FoldSpec"] = ()) -> dict[str, np.ndarray]:
    """Keypoint name -> (3,) m (table frame): the keypoints a camera looking down sees on
    the garment's cloth with vertices (N, 3) (default: its flat vertices), after `folds`
    (in order; the specs as planned, in the flat garment's frame). No folds: exactly
    `garment.keypoints(vertices)`."""
    v = garment.vertices if vertices is None else np.asarray(vertices, dtype=float)
    if v.shape != garment.vertices.shape:
        raise ValueError(f"vertices have shape {v.shape}, the garment has {garment.vertices.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError("vertices contain NaN or inf")
    flat = garment.vertices[:, :2]
    ids = np.array([garment.keypoint_ids[n] for n in KEYPOINT_NAMES])
    outline = flat[ids]
    loc = keypoint_locations(outline, folds)
    out = {n: v[i].copy() for n, i in zip(KEYPOINT_NAMES, ids)}
    changed = np.flatnonzero(np.linalg.norm(loc - outline, axis=1) > 1e-9)
    if len(changed):
        pos = locate(flat, v, loc[changed], folds)
        for j, i in enumerate(changed):
            out[KEYPOINT_NAMES[i]] = pos[j]
    return out
