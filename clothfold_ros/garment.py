"""Polygonal shirt model and its triangle mesh (docs/method.md section 1).

Frame: table frame, metres, z up; the flat shirt is centred at the origin with +x its
right side and +y toward the neck. The 13 outline points are the first mesh vertices,
in `KEYPOINT_NAMES` order, so keypoints are vertex ids 0..12.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

KEYPOINT_NAMES: tuple[str, ...] = (
    "bottom_right",
    "armpit_right",
    "sleeve_bottom_right",
    "sleeve_top_right",
    "shoulder_right",
    "neck_right",
    "neck_middle",
    "neck_left",
    "shoulder_left",
    "sleeve_top_left",
    "sleeve_bottom_left",
    "armpit_left",
    "bottom_left",
)

DEFAULT_MAX_AREA = 1.0 / 20000.0  # m^2, the study's resolution (docs/method.md section 1)


@dataclass(frozen=True)
class ShirtShape:
    """Shirt outline parameters. Lengths are in units of the shirt height (multiplied
    by `scale`, in metres); `sleeve_angle_deg` > 0 points the sleeves down."""

    bottom_width: float
    neck_width: float
    neck_depth: float
    shoulder_width: float
    shoulder_height: float
    sleeve_width_start: float
    sleeve_width_end: float
    sleeve_length: float
    sleeve_angle_deg: float
    scale: float = 0.635

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)):
                raise ValueError(f"ShirtShape.{f.name} must be a number, got {v!r}")
            if not math.isfinite(v):
                raise ValueError(f"ShirtShape.{f.name} must be finite, got {v}")
            object.__setattr__(self, f.name, float(v))
        for name in ("bottom_width", "neck_width", "shoulder_width", "shoulder_height",
                     "sleeve_width_start", "sleeve_width_end", "sleeve_length", "scale"):
            if getattr(self, name) <= 0:
                raise ValueError(f"ShirtShape.{name} must be > 0, got {getattr(self, name)}")
        if not 0.0 <= self.neck_depth < self.shoulder_height:
            raise ValueError(f"ShirtShape.neck_depth must be in [0, shoulder_height), got {self.neck_depth}")
        if self.shoulder_height > 1.0:
            raise ValueError(f"ShirtShape.shoulder_height must be <= 1 (the neck top), got {self.shoulder_height}")
        if self.neck_width >= self.shoulder_width:
            raise ValueError(
                f"ShirtShape.neck_width ({self.neck_width}) must be < shoulder_width ({self.shoulder_width})")
        if not -90.0 < self.sleeve_angle_deg < 90.0:
            raise ValueError(f"ShirtShape.sleeve_angle_deg must be in (-90, 90), got {self.sleeve_angle_deg}")
        a = self.armpit_offset
        if self.sleeve_width_start <= a:
            raise ValueError(
                f"ShirtShape.sleeve_width_start ({self.sleeve_width_start}) must exceed "
                f"|bottom_width - shoulder_width| / 2 = {a}: the armpit is undefined")
        if self.shoulder_height - self.armpit_drop <= 0:
            raise ValueError(
                f"the armpit lies below the hem: shoulder_height ({self.shoulder_height}) must exceed "
                f"sqrt(sleeve_width_start^2 - A^2) = {self.armpit_drop}")
        _check_simple_polygon(_outline_unit(self))

    @property
    def armpit_offset(self) -> float:
        """A = |bottom_width - shoulder_width| / 2 (shirt-height units)."""
        return abs(self.bottom_width - self.shoulder_width) / 2.0

    @property
    def armpit_drop(self) -> float:
        """B = sqrt(sleeve_width_start^2 - A^2): armpit below shoulder (shirt-height units)."""
        return math.sqrt(max(self.sleeve_width_start**2 - self.armpit_offset**2, 0.0))


def _outline_unit(s: ShirtShape) -> np.ndarray:
    """(13, 2) outline in shirt-height units, hem at y = 0 (before centring and scaling)."""
    hem = np.array([s.bottom_width / 2, 0.0])
    neck_top = np.array([s.neck_width / 2, 1.0])
    neck_bottom = np.array([0.0, 1.0 - s.neck_depth])
    shoulder = np.array([s.shoulder_width / 2, s.shoulder_height])
    armpit = np.array([s.bottom_width / 2, s.shoulder_height - s.armpit_drop])
    middle = (shoulder + armpit) / 2
    cuff = middle + np.array([s.sleeve_length, 0.0])
    half = np.array([0.0, s.sleeve_width_end / 2])
    phi = -math.radians(s.sleeve_angle_deg)
    rot = np.array([[math.cos(phi), -math.sin(phi)], [math.sin(phi), math.cos(phi)]])
    cuff_bottom = middle + rot @ (cuff - half - middle)
    cuff_top = middle + rot @ (cuff + half - middle)
    right = np.array([hem, armpit, cuff_bottom, cuff_top, shoulder, neck_top])
    left = right[::-1] * np.array([-1.0, 1.0])
    return np.vstack([right, neck_bottom[None], left])


def shirt_outline(shape: ShirtShape | int = 1) -> np.ndarray:
    """(13, 2) outline in metres, centred (y -= 0.5, then times scale), counter-clockwise,
    in `KEYPOINT_NAMES` order."""
    s = _as_shape(shape)
    return (_outline_unit(s) - np.array([0.0, 0.5])) * s.scale


def _as_shape(shape: ShirtShape | int) -> ShirtShape:
    if isinstance(shape, ShirtShape):
        return shape
    if isinstance(shape, (int, np.integer)) and not isinstance(shape, bool) and int(shape) in SHAPES:
        return SHAPES[int(shape)]
    raise ValueError(f"unknown shirt shape {shape!r}; use a ShirtShape or one of {sorted(SHAPES)}")


def _check_simple_polygon(p: np.ndarray) -> None:
    """Raise ValueError unless the closed polygon p (N, 2) is simple and counter-clockwise."""
    n = len(p)
    a, b = p, np.roll(p, -1, axis=0)
    if np.any(np.linalg.norm(b - a, axis=1) < 1e-9):
        raise ValueError("shirt outline has coincident consecutive points")

    def orient(p0: np.ndarray, p1: np.ndarray, p2: np.ndarray) -> np.ndarray:
        d1, d2 = p1 - p0, p2 - p0
        return d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0]

    i, j = np.triu_indices(n, k=2)
    keep = ~((i == 0) & (j == n - 1))  # first and last edges are adjacent too
    i, j = i[keep], j[keep]
    o1 = orient(a[i], b[i], a[j])
    o2 = orient(a[i], b[i], b[j])
    o3 = orient(a[j], b[j], a[i])
    o4 = orient(a[j], b[j], b[i])
    eps = 1e-12
    crossing = (o1 * o2 <= eps) & (o3 * o4 <= eps)
    # collinear but disjoint segments give all-zero orientations: check their overlap
    collinear = (np.abs(o1) <= eps) & (np.abs(o2) <= eps)
    if np.any(collinear):
        for k in np.flatnonzero(collinear):
            d = b[i[k]] - a[i[k]]
            t = [(q - a[i[k]]) @ d / (d @ d) for q in (a[j[k]], b[j[k]])]
            crossing[k] = max(t) >= 0.0 and min(t) <= 1.0
    if np.any(crossing):
        k = int(np.flatnonzero(crossing)[0])
        raise ValueError(
            f"shirt outline self-intersects: edge {KEYPOINT_NAMES[i[k]]}-{KEYPOINT_NAMES[(i[k] + 1) % n]} "
            f"meets edge {KEYPOINT_NAMES[j[k]]}-{KEYPOINT_NAMES[(j[k] + 1) % n]}")
    area2 = np.sum(a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1])
    if area2 <= 0:
        raise ValueError("shirt outline is not counter-clockwise")


SHAPES: dict[int, ShirtShape] = {
    1: ShirtShape(0.65, 0.32, 0.08, 0.62, 0.90, 0.28, 0.18, 0.76, -3.0),  # long straight sleeves
    2: ShirtShape(0.65, 0.32, 0.08, 0.62, 0.94, 0.28, 0.18, 0.76, 30.0),  # long sleeves angled down
    3: ShirtShape(0.75, 0.25, 0.10, 0.68, 0.95, 0.30, 0.25, 0.22, 5.0),  # short sleeves
}


@dataclass(eq=False)
class Garment:
    """A triangle mesh of a shirt. vertices (N, 3) m (table frame), triangles (M, 3)
    counter-clockwise seen from +z; keypoint_ids maps keypoint names to vertex ids."""

    shape: ShirtShape
    vertices: np.ndarray
    triangles: np.ndarray
    keypoint_ids: dict[str, int]

    def keypoints(self, vertices: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Keypoint name -> (3,) position in `vertices` (N, 3), default the garment's own."""
        v = self.vertices if vertices is None else np.asarray(vertices, dtype=float)
        if v.shape != self.vertices.shape:
            raise ValueError(f"vertices have shape {v.shape}, the garment has {self.vertices.shape}")
        return {name: v[i].copy() for name, i in self.keypoint_ids.items()}

    def to_trimesh(self, vertices: np.ndarray | None = None):
        """A trimesh.Trimesh of the garment (vertices default to its own; not processed)."""
        import trimesh

        v = self.vertices if vertices is None else np.asarray(vertices, dtype=float)
        return trimesh.Trimesh(vertices=v, faces=self.triangles, process=False)

    def boundary_loop(self) -> np.ndarray:
        """Vertex ids of the boundary in counter-clockwise order, starting at vertex 0."""
        e = np.concatenate([self.triangles[:, [0, 1]], self.triangles[:, [1, 2]], self.triangles[:, [2, 0]]])
        key = np.sort(e, axis=1)
        _, inv, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        directed = e[counts[inv.ravel()] == 1]  # boundary edges keep the triangle's CCW direction
        nxt = dict(zip(directed[:, 0].tolist(), directed[:, 1].tolist()))
        loop = [0]
        while len(loop) <= len(nxt):
            v = nxt[loop[-1]]
            if v == 0:
                break
            loop.append(v)
        return np.asarray(loop, dtype=np.int64)


#: m^2, the meshes a shirt may be built with: 1e-6 is about 600K triangles (the study's 5e-5 is 12K),
#: 0.1 a handful; beyond that Triangle fails or the mesh is no shirt
MAX_AREA_RANGE = (1e-6, 0.1)


def make_shirt(shape: ShirtShape | int = 1, max_area: float = DEFAULT_MAX_AREA, z: float = 0.0) -> Garment:
    """Mesh the shirt outline (constrained quality Delaunay, max triangle area `max_area`
    m^2) lying flat at height `z` m. Outline points are vertices 0..12."""
    import triangle

    s = _as_shape(shape)
    if not (math.isfinite(max_area) and MAX_AREA_RANGE[0] <= max_area <= MAX_AREA_RANGE[1]):
        raise ValueError(f"max_area must be a triangle area in m^2 within {MAX_AREA_RANGE[0]:g}..{MAX_AREA_RANGE[1]:g}, "
                         f"got {max_area}")
    if not math.isfinite(z):
        raise ValueError(f"z must be finite, got {z}")
    outline = shirt_outline(s)
    n = len(outline)
    segments = np.column_stack([np.arange(n), (np.arange(n) + 1) % n])
    area = f"{max_area:.18f}".rstrip("0")  # Triangle does not parse exponents like 5e-05
    out = triangle.triangulate({"vertices": outline, "segments": segments}, f"pqa{area}")
    xy = np.asarray(out["vertices"], dtype=float)
    tris = np.asarray(out["triangles"], dtype=np.int64)
    if not np.allclose(xy[:n], outline, atol=1e-12):
        raise RuntimeError("triangle did not keep the outline points as the first vertices")
    a, b, c = xy[tris[:, 0]], xy[tris[:, 1]], xy[tris[:, 2]]
    cw = ((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]) < 0
    tris[cw] = tris[cw][:, [0, 2, 1]]
    vertices = np.column_stack([xy, np.full(len(xy), float(z))])
    return Garment(s, vertices, tris, {name: i for i, name in enumerate(KEYPOINT_NAMES)})
