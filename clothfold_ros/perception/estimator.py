"""Shirt keypoints from a point cloud of the table seen from above (issue 13).

Frame: the cloud is in the table frame (metres, z up, table top z = 0; transform camera
clouds first). Steps:

1. segment: keep finite points in the height band (min_height, max_height] above the
   table; refuse empty / mostly invalid clouds, no cloth, several cloth blobs;
2. top view: rasterise the cloth points (pixel `pixel` m), close small holes, take the
   largest connected component and its outline (OpenCV), and the distance to the mask;
3. fit the parametric shirt (9 shape parameters + scale, docs/method.md section 1) with
   a planar pose (x, y, yaw) and, for a partly folded shirt, the folds done so far (each fold line
   fitted: angle and offset about the line planned from the model's own keypoints) by
   scipy.optimize.least_squares. Residuals: every observed outline point's distance to
   the folded model's outline (flat edges and creases), and how far model outline points
   lie outside the cloth mask (the outline is first moved out by half the point spacing:
   the outermost returns lie that far inside the cloth's edge). Flat: several start shapes
   (short/long, straight/angled sleeves) and headings are ranked and the best fitted;
   folded: the newest fold's line starts at several offsets about the planned one
   (`START_FOLD_OFFSETS`), ranked likewise.
   Hidden parts (a sleeve folded onto the body) cannot be seen in a silhouette: for folded
   states pass the previous stage's estimate (`prior`): its shape and earlier fold lines
   are kept, the pose and the newest fold lines are fitted;
4. keypoints with the folded-state semantics of `visible` (what a camera sees), their z
   the median cloud height around them.

`fit residual` = RMS distance (m) of the observed outline points to the fitted model
outline. Bad clouds raise a `PerceptionError` subclass; a fit whose residual exceeds
`max_residual` raises `PoorFitError` carrying the estimate.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, fields, replace
from typing import Sequence

import numpy as np

from ..folding import FOLD_NAMES, FoldSpec, body_length, fold_spec
from ..garment import KEYPOINT_NAMES, SHAPES, ShirtShape, _outline_unit
from .visible import FoldLine, ideal_visible_keypoints

SHAPE_FIELDS = tuple(f.name for f in fields(ShirtShape))  # 9 parameters + scale
# fit bounds (shirt-height units, deg, m): docs/method.md section 1 plausible ranges, widened a little
SHAPE_BOUNDS = {
    "bottom_width": (0.55, 0.80), "neck_width": (0.15, 0.45), "neck_depth": (0.0, 0.25),
    "shoulder_width": (0.38, 0.82), "shoulder_height": (0.80, 0.99), "sleeve_width_start": (0.20, 0.36),
    "sleeve_width_end": (0.12, 0.24), "sleeve_length": (0.03, 1.05), "sleeve_angle_deg": (-15.0, 65.0),
    "scale": (0.3, 1.2),
}
OUTSIDE_WEIGHT = 1.0  # weight of model outline outside the cloth against observed outline missed by the model
START_SLEEVES = ((0.76, -3.0), (0.76, 25.0), (0.76, 50.0), (0.4, 10.0), (0.4, 45.0), (0.15, 10.0))  # length, deg
FOLD_ANGLE_RANGE = math.radians(15.0)  # fitted fold line angle within +- this of the planned one
FOLD_OFFSET_RANGE = 0.1  # m, fitted fold line offset within +- this of the planned one
MAX_CREASE = 0.05  # m, the visible crease lies at most this far inside the fold line (the bulge)
FOLD_PARAMS = 3  # per fitted fold: angle and offset about the planned line, crease
# offsets (m) of the newest fold's line about the planned one that the fit may start from: a fold
# that landed off its plan can hide the edge the planned line would show (a middle fold 2 cm
# toward the shoulders lays the hem over them), and from the planned line least_squares then
# moves the whole shirt instead of the line
START_FOLD_OFFSETS = (0.0, -0.025, 0.025, -0.05, 0.05, -0.075, 0.075)
# a fold line FOLD_PRIOR_ANGLE rad or FOLD_PRIOR_OFFSET m off the planned one costs as much as
# one outline point FOLD_PRIOR_WEIGHT m off the model
FOLD_PRIOR_ANGLE, FOLD_PRIOR_OFFSET, FOLD_PRIOR_WEIGHT = 0.1, 0.02, 0.003


class PerceptionError(ValueError):
    """A cloud from which no keypoints can be estimated."""


class BadCloudError(PerceptionError):
    """Empty, malformed or mostly invalid (NaN) cloud."""


class NoClothError(PerceptionError):
    """Too few points or too small an area above the table."""


class MultipleBlobsError(PerceptionError):
    """More than one cloth-sized blob on the table."""


class FitError(PerceptionError):
    """The model fit did not converge."""


class PoorFitError(PerceptionError):
    """The fit converged but its residual is too large; `estimate` holds it."""

    def __init__(self, message: str, estimate: "KeypointEstimate") -> None:
        super().__init__(message)
        self.estimate = estimate


@dataclass(frozen=True)
class EstimatorConfig:
    """pixel: top-view raster size (m); min_height/max_height: cloth height band (m above the
    table); max_invalid_fraction: refuse clouds with more non-finite points; min_points,
    min_area (m^2): less is 'no cloth', a blob over max_area (m^2) is the table; blob_fraction: a second blob at least this fraction
    of the largest is 'two blobs'; contour_points: outline points fitted; max_residual (m);
    max_nfev: function evaluations per fit; tolerance: least_squares
    ftol = xtol = gtol; spacing: model outline sample spacing (m); max_starts: fits tried
    from the best-ranked starts until one's residual is under good_enough x max_residual."""

    pixel: float = 0.005
    min_height: float = -0.01
    max_height: float = 0.25
    max_invalid_fraction: float = 0.5
    min_points: int = 200
    min_area: float = 0.02
    max_area: float = 1.2
    blob_fraction: float = 0.05
    contour_points: int = 200
    max_residual: float = 0.01
    max_nfev: int = 400
    tolerance: float = 1e-4
    max_starts: int = 3
    good_enough: float = 0.5
    spacing: float = 0.015

    def __post_init__(self) -> None:
        positive = ("pixel", "max_residual", "tolerance", "spacing", "max_area")
        bad = [k for k in positive if not (math.isfinite(getattr(self, k)) and getattr(self, k) > 0)]
        bad += [k for k in ("min_points", "max_nfev", "max_starts") if not getattr(self, k) >= 1]
        bad += [k for k in ("max_invalid_fraction", "blob_fraction", "good_enough") if not 0.0 <= getattr(self, k) <= 1.0]
        if not self.contour_points >= 3:
            bad.append("contour_points")
        if not (math.isfinite(self.min_area) and 0.0 <= self.min_area < self.max_area):
            bad.append("min_area")
        if not (math.isfinite(self.min_height) and math.isfinite(self.max_height) and self.min_height < self.max_height):
            bad.append("min_height/max_height")
        if bad:
            raise ValueError(f"EstimatorConfig: bad {', '.join(bad)} ({self})")


@dataclass
class KeypointEstimate:
    """keypoints: name -> (3,) m (table frame, visible semantics); shape: fitted ShirtShape;
    pose: (x m, y m, yaw rad) of the shirt frame in the table frame; folds: fitted fold lines
    (table frame); residual: RMS distance (m) of the observed outline to the model's;
    outline: (K, 2) model outline sample points and segments: (S, 2, 2) the model's outline
    and creases as line segments (table frame); n_points: cloth points used; nfev: model
    evaluations; seconds: CPU time (process) of the estimate."""

    keypoints: dict[str, np.ndarray]
    shape: ShirtShape
    pose: tuple[float, float, float]
    folds: list[FoldLine]
    residual: float
    outline: np.ndarray
    segments: np.ndarray = field(repr=False)  # (S, 2, 2) model outline segments, table frame
    n_points: int = 0
    nfev: int = 0
    seconds: float = 0.0


# -- segmentation and top view ---------------------------------------------------------------
def finite_mask(points: np.ndarray, config: EstimatorConfig = EstimatorConfig()) -> np.ndarray:
    """(N,) bool, the finite points of a cloud (N, 3); BadCloudError when it is empty, not
    (N, 3) or more than `max_invalid_fraction` of it is NaN/inf."""
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3:
        raise BadCloudError(f"cloud must have shape (N, 3), got {p.shape}")
    if len(p) == 0:
        raise BadCloudError("cloud is empty")
    finite = np.all(np.isfinite(p), axis=1)
    bad = 1.0 - finite.mean()
    if bad > config.max_invalid_fraction:
        raise BadCloudError(f"{bad:.0%} of the cloud's {len(p)} points are NaN/inf "
                            f"(more than {config.max_invalid_fraction:.0%})")
    return finite


def segment(points: np.ndarray, config: EstimatorConfig = EstimatorConfig()) -> np.ndarray:
    """Cloth points (P, 3) of a cloud (N, 3) in the table frame; PerceptionError if unusable."""
    p = np.asarray(points, dtype=float)
    p = p[finite_mask(p, config)]
    cloth = p[(p[:, 2] > config.min_height) & (p[:, 2] <= config.max_height)]
    if len(cloth) < config.min_points:
        raise NoClothError(f"no cloth on the table: {len(cloth)} of {len(p)} points in the height band "
                           f"({config.min_height:g}, {config.max_height:g}] m (need {config.min_points})")
    return cloth


@dataclass
class TopView:
    """Largest cloth blob seen from above: mask (H, W) uint8, origin (x, y) m of pixel (0, 0)'s
    corner, pixel m, contour (C, 2) m (table frame, the estimated cloth edge), outside (H, W)
    distance (m) beyond the cloth edge, area m^2."""

    mask: np.ndarray
    origin: np.ndarray
    pixel: float
    contour: np.ndarray
    outside: np.ndarray
    area: float
    spacing: float  # m, mean distance between cloud points on the cloth

    def distance_outside(self, xy: np.ndarray) -> np.ndarray:
        """Distance (m) of points (N, 2) outside the mask (0 inside), bilinear; far = large."""
        from scipy.ndimage import map_coordinates

        ij = (xy - self.origin) / self.pixel - 0.5
        d = map_coordinates(self.outside, [ij[:, 1], ij[:, 0]], order=1, mode="nearest")
        # beyond the raster: add the distance to its border
        h, w = self.outside.shape
        over = np.maximum(0, np.maximum(-ij[:, 0], ij[:, 0] - (w - 1))) + np.maximum(
            0, np.maximum(-ij[:, 1], ij[:, 1] - (h - 1)))
        return d + over * self.pixel


def top_view(cloth: np.ndarray, config: EstimatorConfig = EstimatorConfig()) -> TopView:
    """Rasterise cloth points (P, 3), keep the largest blob, its outline and distance map."""
    import cv2

    px = config.pixel
    margin = 4
    lo = cloth[:, :2].min(axis=0) - margin * px
    span = (cloth[:, :2].max(axis=0) - lo) / px + margin + 1  # pixels, in float: no integer overflow
    if not np.all(np.isfinite(span)) or span[0] * span[1] > 4000 * 4000:
        raise BadCloudError(f"cloud spans {span[0] * px:.3g} x {span[1] * px:.3g} m: not a shirt on a table")
    ij = np.floor((cloth[:, :2] - lo) / px).astype(np.int64)
    w, h = ij.max(axis=0) + margin + 1
    mask = np.zeros((h, w), np.uint8)
    mask[ij[:, 1], ij[:, 0]] = 255
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
    mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, kernel)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if n < 2:
        raise NoClothError("no cloth blob in the top view")
    areas = stats[1:, cv2.CC_STAT_AREA] * px * px
    order = np.argsort(areas)[::-1]
    if areas[order[0]] < config.min_area:
        raise NoClothError(f"largest blob is {areas[order[0]]:.3f} m^2 (a shirt needs >= {config.min_area:g} m^2)")
    if areas[order[0]] > config.max_area:
        raise NoClothError(f"largest blob is {areas[order[0]]:.2f} m^2, more than any shirt (max_area "
                           f"{config.max_area:g} m^2): the table is not separated from the cloth (drop its points: table_color for an RGB-D cloud, or a "
                           "mask upstream; a height band only works for cloth thicker than the depth noise)")
    if len(order) > 1 and areas[order[1]] >= config.blob_fraction * areas[order[0]]:
        raise MultipleBlobsError(f"{int(np.sum(areas >= config.blob_fraction * areas[order[0]]))} separate blobs "
                                 f"on the table ({areas[order[0]]:.3f} and {areas[order[1]]:.3f} m^2): "
                                 "expected one shirt")
    mask = np.where(labels == order[0] + 1, 255, 0).astype(np.uint8)
    mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, kernel)
    # fill holes: the cloth is one sheet seen from above
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    c = max(contours, key=cv2.contourArea)
    mask = np.zeros_like(mask)
    cv2.drawContours(mask, [c], -1, 255, thickness=cv2.FILLED)
    contour = (c[:, 0, :].astype(float) + 0.5) * px + lo
    # the outermost returns lie on average half a point spacing inside the cloth's edge:
    # move the outline out by that much along its normal
    n_in = int(np.count_nonzero(mask[ij[:, 1], ij[:, 0]]))
    spacing = math.sqrt(cv2.countNonZero(mask) * px * px / max(n_in, 1))
    tangent = np.roll(contour, -3, axis=0) - np.roll(contour, 3, axis=0)
    normal = np.column_stack([tangent[:, 1], -tangent[:, 0]])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    probe = np.floor((contour + 2 * px * normal - lo) / px).astype(int)
    probe = np.clip(probe, 0, [w - 1, h - 1])
    if np.mean(mask[probe[:, 1], probe[:, 0]] > 0) > 0.5:
        normal = -normal  # the normal must point out of the mask
    contour = contour + 0.5 * spacing * normal
    outside = cv2.distanceTransform(255 - mask, cv2.DIST_L2, 5).astype(float) * px
    outside = np.maximum(outside - 0.5 * (spacing + px), 0.0)
    return TopView(mask, lo, px, contour, outside, float(areas[order[0]]), spacing)


# -- the shirt model ------------------------------------------------------------------------
class _Params:
    """Duck-typed ShirtShape for garment._outline_unit without validation (fit iterates)."""

    armpit_offset = ShirtShape.armpit_offset
    armpit_drop = ShirtShape.armpit_drop

    def __init__(self, values: np.ndarray) -> None:
        for k, v in zip(SHAPE_FIELDS, values):
            setattr(self, k, float(v))


def model_outline(shape_values: np.ndarray) -> np.ndarray:
    """(13, 2) outline (m, shirt frame: centred, +y to the neck) of shape parameters in
    SHAPE_FIELDS order (unvalidated)."""
    s = _Params(shape_values)
    return (_outline_unit(s) - np.array([0.0, 0.5])) * s.scale


def flat_area(shape: ShirtShape) -> float:
    """Area (m^2) of the flat shirt of a fitted shape (its 13-corner outline)."""
    o = model_outline(np.array([getattr(shape, f) for f in SHAPE_FIELDS], dtype=float))
    x, y = o[:, 0], o[:, 1]
    return float(abs(x @ np.roll(y, -1) - y @ np.roll(x, -1)) / 2)


def _rot(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s], [s, c]])


def _line(point: np.ndarray, angle: float, side: float) -> FoldLine:
    d = np.array([math.cos(angle), math.sin(angle)])
    return FoldLine("", point, side * np.array([-d[1], d[0]]))


def _fold_xy(p: np.ndarray, lines: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """Mirror points (N, 2) through (point, normal) lines in turn; (folded, (N, K) moved)."""
    p = p.copy()
    moved = np.zeros((len(p), len(lines)), bool)
    for k, (q, n) in enumerate(lines):
        s = (p - q) @ n
        m = s > 1e-9
        p[m] -= 2 * s[m, None] * n
        moved[:, k] = m
    return p, moved


class _Model:
    """Outline samples of the folded shirt model for a parameter vector."""

    def __init__(self, shape0: np.ndarray, fold_names: Sequence[str], free_shape: bool, spacing: float = 0.01,
                 fixed: Sequence[FoldLine] = ()):
        self.names = list(fold_names)
        self.fixed = list(fixed)  # the first folds' lines, shirt frame, kept as they are
        self.free_shape = free_shape
        self.shape0 = np.asarray(shape0, float)
        o = model_outline(self.shape0)
        lengths = np.linalg.norm(np.roll(o, -1, axis=0) - o, axis=1)
        self.counts = np.maximum(3, np.ceil(lengths / spacing).astype(int))
        self.edge = np.repeat(np.arange(13), self.counts)
        self.edge_next = (self.edge + 1) % 13
        self.sa0 = np.arange(len(self.edge))
        self.sb0 = (self.sa0 + 1) % len(self.edge)
        self.u = np.concatenate([np.arange(c) / c for c in self.counts])
        self.crease_u = np.linspace(0.0, 1.0, 32)
        self.max_points = len(self.u) + len(self.crease_u) * len(self.names)
        self.nominal = self._nominal_lines(self.shape0)

    def _nominal_lines(self, shape: np.ndarray) -> list[tuple[np.ndarray, float, float]]:
        """(point, angle, side) per fold, planned like the pipeline from the model's visible keypoints."""
        out: list[tuple[np.ndarray, float, float]] = []
        done: list[FoldLine] = list(self.fixed)
        o = model_outline(shape)
        length = body_length({k: np.array([x, y, 0.0]) for k, (x, y) in zip(KEYPOINT_NAMES, o)})
        for name in self.names[len(self.fixed):]:
            kp2 = ideal_visible_keypoints(o, done)
            kp = {k: np.array([x, y, 0.0]) for k, (x, y) in zip(KEYPOINT_NAMES, kp2)}
            spec = fold_spec(name, kp, folds_done=[ln.name for ln in done], body_length=length)
            d, n = spec.line_direction[:2], spec.normal[:2]
            side = 1.0 if d[0] * n[1] - d[1] * n[0] > 0 else -1.0
            out.append((spec.line_point[:2].copy(), math.atan2(d[1], d[0]), side))
            done.append(FoldLine(name, spec.line_point[:2].copy(), n.copy()))
        return out

    def split(self, x: np.ndarray):
        """(shape values, pose (3,), fold parameters (K, 3)) of a parameter vector."""
        i = 0
        shape = self.shape0
        if self.free_shape:
            shape = x[:len(SHAPE_FIELDS)]
            i = len(SHAPE_FIELDS)
        pose = x[i:i + 3]
        f = x[i + 3:].reshape(-1, FOLD_PARAMS)
        return shape, pose, f

    def lines(self, f: np.ndarray) -> list[FoldLine]:
        """Fold lines in the shirt frame for the fold parameters (K, 3) = (d angle rad,
        d offset m, crease m) about the planned lines; the earlier, fixed ones first."""
        out = list(self.fixed)
        for (p, a, s), (da, dn, crease), name in zip(self.nominal, f, self.names[len(self.fixed):]):
            ln = _line(p, a + da, s)
            out.append(FoldLine(name, p + dn * ln.normal, ln.normal, float(crease)))
        return out

    def samples(self, x: np.ndarray):
        """(points (M, 2) table frame, segment start ids, segment end ids) of the folded model:
        flat outline samples and, per fold, its crease (the visible fold edge across the
        cloth as it lay then), mirrored fold by fold across the fold lines; cloth between a
        crease and its line (the fold's bulge) and segments cut by a fold are dropped."""
        shape, pose, f = self.split(x)
        o = model_outline(shape)
        a = o[self.edge]
        pts = a + self.u[:, None] * (o[self.edge_next] - a)
        sa, sb = self.sa0, self.sb0
        sig = np.zeros(len(pts), np.int64)  # bit k: moved by fold k; bit 62: taken up by a bulge
        hidden = np.int64(1) << 62
        for k, ln in enumerate(self.lines(f)):
            q, n = ln.point, ln.normal
            s = (pts - q) @ n
            sc = s + ln.crease  # from the crease
            cross = (sig[sa] == sig[sb]) & ((sc[sa] > 0) != (sc[sb] > 0))
            if np.count_nonzero(cross) >= 2:
                i, j = sa[cross], sb[cross]
                t = sc[i] / (sc[i] - sc[j])
                d = np.array([-n[1], n[0]])
                qc = q - ln.crease * n
                along = (pts[i] + t[:, None] * (pts[j] - pts[i]) - qc) @ d
                crease = qc + d * (along.min() + self.crease_u[:, None] * (along.max() - along.min()))
                idx = np.arange(len(pts), len(pts) + len(crease))
                pts = np.vstack([pts, crease])
                sig = np.r_[sig, np.zeros(len(crease), np.int64)]
                s = np.r_[s, np.full(len(crease), -ln.crease)]
                sc = np.r_[sc, np.zeros(len(crease))]
                sa, sb = np.r_[sa, idx[:-1]], np.r_[sb, idx[1:]]
            m = s > 1e-9
            pts[m] -= 2 * s[m, None] * n
            sig[m] |= np.int64(1) << k
            sig[(sc > 1e-9) & ~m] |= hidden
        ok = (sig[sa] == sig[sb]) & (sig[sa] & hidden == 0)
        keep = sig & hidden == 0
        new = np.cumsum(keep) - 1
        return pts[keep] @ _rot(pose[2]).T + pose[:2], new[sa[ok]], new[sb[ok]]


def _candidates(contour: np.ndarray, pts: np.ndarray, sa: np.ndarray, sb: np.ndarray):
    """Per contour point (C, 2): the model segments at its two nearest model points, as point
    index pairs (C, 4, 2) (-1 = none), and its nearest model point (C,)."""
    from scipy.spatial import cKDTree

    _, near = cKDTree(pts).query(contour, k=2)
    after = np.full(len(pts), -1)
    before = np.full(len(pts), -1)
    after[sa] = np.arange(len(sa))
    before[sb] = np.arange(len(sb))
    seg = np.concatenate([after[near], before[near]], axis=1)  # (C, 4) segment ids, -1 = none
    pairs = np.stack([sa[np.maximum(seg, 0)], sb[np.maximum(seg, 0)]], axis=2)
    pairs[seg < 0] = -1
    return pairs, near[:, 0]


def _candidate_distances(contour: np.ndarray, pts: np.ndarray, pairs: np.ndarray, nearest: np.ndarray) -> np.ndarray:
    """Distance (m) of each contour point to the nearest of its candidate segments / point."""
    a, b = pts[np.maximum(pairs[..., 0], 0)], pts[np.maximum(pairs[..., 1], 0)]  # (C, 4, 2)
    ab = b - a
    q = contour[:, None, :]
    t = np.clip(np.sum((q - a) * ab, axis=2) / np.maximum(np.sum(ab * ab, axis=2), 1e-18), 0.0, 1.0)
    d = np.linalg.norm(q - (a + t[..., None] * ab), axis=2)
    d[pairs[..., 0] < 0] = np.inf
    return np.minimum(d.min(axis=1), np.linalg.norm(contour - pts[nearest], axis=1))


def _outline_distances(contour: np.ndarray, pts: np.ndarray, sa: np.ndarray, sb: np.ndarray) -> np.ndarray:
    """Distance (m) of each contour point (C, 2) to the nearest model segment (pts[sa], pts[sb]),
    searched among the segments at the two model points nearest to it."""
    return _candidate_distances(contour, pts, *_candidates(contour, pts, sa, sb))


# -- the estimator ----------------------------------------------------------------------------
def _shape_vector(shape: ShirtShape) -> np.ndarray:
    return np.array([getattr(shape, k) for k in SHAPE_FIELDS], float)


def _moments(xy: np.ndarray) -> tuple[np.ndarray, float]:
    c = xy.mean(axis=0)
    cov = np.cov((xy - c).T)
    w, v = np.linalg.eigh(cov)
    major = v[:, np.argmax(w)]
    return c, math.atan2(major[1], major[0])


def _area_points(outline: np.ndarray, spacing: float = 0.02) -> np.ndarray:
    import shapely

    poly = shapely.Polygon(outline)
    x0, y0, x1, y1 = poly.bounds
    gx, gy = np.meshgrid(np.arange(x0, x1, spacing), np.arange(y0, y1, spacing))
    inside = shapely.contains_xy(poly, gx, gy)
    return np.column_stack([gx[inside], gy[inside]])


def check_fold_names(names: Sequence[str]) -> None:
    """ValueError for a fold name that is not a fold or one listed twice (each is done once)."""
    unknown = [n for n in names if n not in FOLD_NAMES]
    if unknown:
        raise ValueError(f"unknown folds {unknown}; known: {', '.join(FOLD_NAMES)}")
    if len(set(names)) != len(names):
        raise ValueError(f"a fold listed twice in {list(names)}: each fold is done once")


def estimate_keypoints(points: np.ndarray, folds: Sequence[str | FoldSpec | FoldLine] = (),
                       prior: KeypointEstimate | None = None, shape_prior: ShirtShape | None = None,
                       pose_prior: Sequence[float] | None = None,
                       config: EstimatorConfig = EstimatorConfig()) -> KeypointEstimate:
    """Estimate the shirt's visible keypoints from a cloud (N, 3) m in the table frame.

    folds: the folds done so far, in order (names, or specs whose names are used; the lines
    are fitted, starting from the lines planned from the model's own keypoints).
    prior: the estimate of an earlier stage of the same shirt: its shape is kept, its pose
    is the start, and the folds it had fitted keep their lines (relative to the shirt) when
    `folds` starts with them; only the newer folds' lines are fitted (a fold hides most of
    the earlier creases). shape_prior / pose_prior (x m, y m, yaw rad) without a prior: the
    shape kept fixed when folds are given (else the start of the fit), the pose to start
    from (else the blob's moments, best of four headings)."""
    from scipy.optimize import least_squares

    tic = time.process_time()
    names = [f if isinstance(f, str) else f.name for f in folds]
    check_fold_names(names)
    cloth = segment(points, config)
    view = top_view(cloth, config)
    step = max(1, len(view.contour) // config.contour_points)
    contour = view.contour[::step]

    fixed: list[FoldLine] = []
    if prior is not None:
        shape_prior, pose_prior = prior.shape, prior.pose
        prior_names = [ln.name for ln in prior.folds]
        if names[:len(prior_names)] == prior_names:
            r_inv = _rot(-prior.pose[2])
            t = np.asarray(prior.pose[:2])
            fixed = [FoldLine(ln.name, r_inv @ (ln.point - t), r_inv @ ln.normal, ln.crease) for ln in prior.folds]
    free_shape = not names or shape_prior is None
    lo_s = np.array([SHAPE_BOUNDS[k][0] for k in SHAPE_FIELDS])
    hi_s = np.array([SHAPE_BOUNDS[k][1] for k in SHAPE_FIELDS])
    if shape_prior is not None:
        shapes = [_shape_vector(shape_prior)]
    else:  # area-matched starts with short/long, straight/angled sleeves
        import shapely

        shapes = []
        for length, angle in START_SLEEVES:
            v = _shape_vector(replace(SHAPES[1], sleeve_length=length, sleeve_angle_deg=angle))
            v[-1] *= math.sqrt(view.area / shapely.Polygon(model_outline(v)).area)
            shapes.append(np.clip(v, lo_s + 1e-6, hi_s - 1e-6))
    n_f = len(names) - len(fixed)
    f_lo = np.tile([-FOLD_ANGLE_RANGE, -FOLD_OFFSET_RANGE, 0.0], n_f)
    f_hi = np.tile([FOLD_ANGLE_RANGE, FOLD_OFFSET_RANGE, MAX_CREASE], n_f)

    def residuals(x: np.ndarray, mdl: _Model, assoc=None) -> np.ndarray:
        """Outline distances (C,), model points outside the cloth (M,), fold line prior (2K,).
        assoc: contour-to-model candidate segments to keep (for the Jacobian's differences)."""
        pts, sa, sb = mdl.samples(x)
        if assoc is None or len(pts) != assoc[2]:
            r1 = _outline_distances(contour, pts, sa, sb)
        else:
            r1 = _candidate_distances(contour, pts, assoc[0], assoc[1])
        r2 = np.zeros(mdl.max_points)  # fixed length: a crease may vanish (its line off the cloth)
        r2[:len(pts)] = view.distance_outside(pts) * (OUTSIDE_WEIGHT * math.sqrt(len(contour) / mdl.max_points))
        # weak pull of the fitted fold lines toward the planned ones (where a crease is hidden)
        r3 = FOLD_PRIOR_WEIGHT * (mdl.split(x)[2] / [FOLD_PRIOR_ANGLE, FOLD_PRIOR_OFFSET, FOLD_PRIOR_OFFSET]).ravel()
        return np.concatenate([r1, r2, r3])

    def jacobian(x: np.ndarray, mdl: _Model, steps: np.ndarray) -> np.ndarray:
        """Forward differences with the contour-to-model association of x kept fixed."""
        pts, sa, sb = mdl.samples(x)
        pairs, nearest = _candidates(contour, pts, sa, sb)
        assoc = (pairs, nearest, len(pts))
        f0 = residuals(x, mdl, assoc)
        jac = np.empty((len(f0), len(x)))
        for j, h in enumerate(steps):
            xj = x.copy()
            xj[j] += h
            jac[:, j] = (residuals(xj, mdl, assoc) - f0) / h
        return jac

    def pack(shape, pose, f):
        return np.concatenate([shape if free_shape else [], pose, np.ravel(f)])

    # starts: each start shape with its area moments aligned to the blob's (four headings),
    # or the given pose, and the newest fold's line at START_FOLD_OFFSETS; ranked by their cost
    # as they are
    cm, yaw_m = _moments(_mask_points(view))
    fold_starts = []
    for offset in START_FOLD_OFFSETS if n_f else (0.0,):
        f0 = np.tile([0.0, 0.0, 0.002], (n_f, 1))
        if n_f:
            f0[-1, 1] = offset
        fold_starts.append(f0)
    starts = []
    for shape0 in shapes:
        coarse = _Model(shape0, names, False, spacing=0.03, fixed=fixed)
        if pose_prior is not None:
            poses = [np.asarray(pose_prior, float)]
        else:
            folded_area, _ = _fold_xy(_area_points(model_outline(shape0)),
                                      [(ln.point, ln.normal) for ln in coarse.lines(np.zeros((n_f, FOLD_PARAMS)))])
            cmod, yaw_mod = _moments(folded_area)
            poses = [np.r_[cm - _rot(yaw) @ cmod, yaw]
                     for yaw in (yaw_m - yaw_mod + k * math.pi / 2 for k in range(4))]
        for p0 in poses:
            for f0 in fold_starts:
                r = residuals(np.r_[p0, f0.ravel()], coarse)
                starts.append((float(np.sum(np.sqrt(1.0 + (r / 0.01) ** 2) - 1.0)), len(starts), shape0, p0, f0))
    starts.sort(key=lambda t: t[:2])

    def fit_from(shape0: np.ndarray, p0: np.ndarray, f0: np.ndarray):
        model = _Model(shape0, names, free_shape, spacing=config.spacing, fixed=fixed)
        lo = pack(lo_s, np.r_[p0[:2] - 0.3, p0[2] - math.pi], f_lo)
        hi = pack(hi_s, np.r_[p0[:2] + 0.3, p0[2] + math.pi], f_hi)
        x_scale = pack(np.r_[[0.05] * 8, 5.0, 0.05], [0.02, 0.02, 0.05], np.tile([0.05, 0.02, 0.01], n_f))
        x0 = np.clip(pack(shape0, p0, f0), lo + 1e-9, hi - 1e-9)
        steps = 1e-4 * x_scale
        fit = least_squares(residuals, x0, jac=lambda x, mdl: jacobian(x, mdl, steps), args=(model,),
                            bounds=(lo, hi), loss="soft_l1", f_scale=0.005,
                            max_nfev=config.max_nfev, x_scale=x_scale, ftol=config.tolerance,
                            xtol=config.tolerance, gtol=config.tolerance)
        pts, sa, sb = model.samples(fit.x)
        return model, fit, float(np.sqrt(np.mean(_outline_distances(contour, pts, sa, sb) ** 2)))

    # folded: the best-ranked start and the best-ranked one from the planned line are both fitted
    # (either alone can end in a shifted shirt whose residual passes), the lower residual wins
    planned = next((t for t in starts if not n_f or t[4][-1, 1] == 0.0), starts[0])
    first = [starts[0]] if planned is starts[0] else [starts[0], planned]
    order = first + [t for t in starts if all(t is not u for u in first)]
    best, nfev, invalid = None, 0, None
    for k, (_, _, shape0, p0, f0) in enumerate(order[:max(config.max_starts, len(first))]):
        model, fit, resid = fit_from(shape0, p0, f0)
        nfev += fit.nfev
        if fit.status > 0 and np.all(np.isfinite(fit.x)):
            try:  # a fit that ends in no shirt's shape (free shape only) is not a candidate
                shape = ShirtShape(*model.split(fit.x)[0])
            except ValueError as err:
                invalid = invalid or err
            else:
                if best is None or resid < best[2]:
                    best = (model, fit, resid, shape)
        if k + 1 >= len(first) and best is not None and best[2] <= config.good_enough * config.max_residual:
            break  # good enough: the next starts rank worse
    if best is None and invalid is not None:
        raise FitError(f"fitted shirt shape is invalid: {invalid}") from invalid
    if best is None:
        raise FitError(f"shirt model fit did not converge: {fit.message} ({nfev} evaluations)")
    model, fit, resid, shape = best
    shape_v, pose, f = model.split(fit.x)
    pts, sa, sb = model.samples(fit.x)
    r = _rot(pose[2])
    lines_shirt = model.lines(f)
    kp2 = ideal_visible_keypoints(model_outline(shape_v), lines_shirt) @ r.T + pose[:2]
    lines = [FoldLine(ln.name, r @ ln.point + pose[:2], r @ ln.normal, ln.crease) for ln in lines_shirt]
    keypoints = _with_height(kp2, cloth)
    yaw = math.atan2(math.sin(pose[2]), math.cos(pose[2]))
    est = KeypointEstimate(keypoints, shape, (float(pose[0]), float(pose[1]), yaw), lines, resid, pts,
                           np.stack([pts[sa], pts[sb]], axis=1), len(cloth), int(nfev),
                           time.process_time() - tic)
    if not resid <= config.max_residual:
        raise PoorFitError(f"fit residual {resid * 1e3:.1f} mm exceeds max_residual "
                           f"{config.max_residual * 1e3:.1f} mm: the cloud does not look like the shirt model "
                           f"with folds [{', '.join(names)}]", est)
    return est


def _mask_points(view: TopView) -> np.ndarray:
    iy, ix = np.nonzero(view.mask)
    return (np.column_stack([ix, iy]) + 0.5) * view.pixel + view.origin


def _with_height(kp2: np.ndarray, cloth: np.ndarray, radius: float = 0.02) -> dict[str, np.ndarray]:
    """Keypoints (13, 2) with z = the median cloud height within `radius` m (0 if none)."""
    from scipy.spatial import cKDTree

    tree = cKDTree(cloth[:, :2])
    out = {}
    for name, p in zip(KEYPOINT_NAMES, kp2):
        idx = tree.query_ball_point(p, radius)
        z = float(np.median(cloth[idx, 2])) if idx else 0.0
        out[name] = np.array([p[0], p[1], max(z, 0.0)])
    return out

