"""A depth camera looking straight down at the table, as a point-cloud source.

Frame: table frame, metres, z up, table top z = 0. The camera is orthographic (a height
map): one ray per pixel of a regular grid of pitch `pitch` m over the view rectangle,
returning the top-most cloth surface hit (z-buffer over the mesh triangles), so covered
layers are not seen. Each return gets Gaussian depth noise (std `noise` m, along z) and is
dropped with probability `dropout`; `table=True` also returns the table (z = 0) where no
cloth is hit, like an unmasked depth image. `colour_cloud` adds each return's colour, as an
RGB-D camera's: the cloth's or the table's, with Gaussian noise (8-bit RGB).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class DepthCamera:
    """pitch: pixel size on the table (m); view: (x_min, x_max, y_min, y_max) m; noise: depth
    noise std (m); dropout: fraction of returns lost (-); table: return table pixels too;
    cloth_rgb / table_rgb / colour_noise: colours (0-255) and their noise std for `colour_cloud`."""

    pitch: float = 0.004
    view: tuple[float, float, float, float] = (-1.0, 1.0, -0.7, 0.7)
    noise: float = 0.002
    dropout: float = 0.1
    table: bool = False
    cloth_rgb: tuple[int, int, int] = (200, 205, 215)  # a light shirt
    table_rgb: tuple[int, int, int] = (60, 45, 35)  # a dark wooden table
    colour_noise: float = 8.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.pitch) and self.pitch > 0):
            raise ValueError(f"pitch must be > 0 m, got {self.pitch}")
        x0, x1, y0, y1 = (float(v) for v in self.view)
        if not (x1 > x0 and y1 > y0 and all(math.isfinite(v) for v in self.view)):
            raise ValueError(f"view must be (x_min, x_max, y_min, y_max) with min < max, got {self.view}")
        if not (math.isfinite(self.noise) and self.noise >= 0):
            raise ValueError(f"noise must be >= 0 m, got {self.noise}")
        if not 0.0 <= self.dropout < 1.0:
            raise ValueError(f"dropout must be in [0, 1), got {self.dropout}")
        for name in ("cloth_rgb", "table_rgb"):
            c = getattr(self, name)
            if len(c) != 3 or not all(0 <= v <= 255 for v in c):
                raise ValueError(f"{name} must be 3 values in 0..255, got {c}")
        if not (math.isfinite(self.colour_noise) and self.colour_noise >= 0):
            raise ValueError(f"colour_noise must be >= 0, got {self.colour_noise}")

    def height_map(self, vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(xs (W,), ys (H,), z (H, W)): top surface height (m) at the pixel centres, NaN where
        no triangle covers the pixel."""
        v = np.asarray(vertices, dtype=float)
        tri = np.asarray(triangles, dtype=np.int64)
        if v.ndim != 2 or v.shape[1] != 3 or not np.isfinite(v).all():
            raise ValueError("vertices must be a finite (N, 3) array (m)")
        if len(tri) and (tri.ndim != 2 or tri.shape[1] != 3 or tri.min() < 0 or tri.max() >= len(v)):
            raise ValueError(f"triangles must be (M, 3) indices into the {len(v)} vertices")
        x0, x1, y0, y1 = self.view
        xs = np.arange(x0 + self.pitch / 2, x1, self.pitch)
        ys = np.arange(y0 + self.pitch / 2, y1, self.pitch)
        zbuf = np.full(len(xs) * len(ys), -np.inf)
        if len(tri):
            a, b, c = v[tri[:, 0]], v[tri[:, 1]], v[tri[:, 2]]
            lo = np.floor((np.minimum(np.minimum(a, b), c)[:, :2] - [x0, y0]) / self.pitch - 0.5).astype(int) + 1
            hi = np.floor((np.maximum(np.maximum(a, b), c)[:, :2] - [x0, y0]) / self.pitch - 0.5).astype(int)
            lo, hi = np.maximum(lo, 0), np.minimum(hi, [len(xs) - 1, len(ys) - 1])  # pixels in the view only
            extent = (hi - lo).max(axis=1) + 1  # pixels across each triangle's box (<= 0: outside the view)
            # triangles rasterised in groups of similar size: one stretched triangle does not size
            # the candidate grid of all the others
            size = 2 ** np.ceil(np.log2(np.maximum(extent, 1))).astype(int)
            for span in np.unique(size[extent > 0]):
                sel = np.flatnonzero((size == span) & (extent > 0))
                self._rasterise(zbuf, a[sel], b[sel], c[sel], lo[sel], hi[sel], int(span), len(xs), len(ys))
        zbuf[~np.isfinite(zbuf)] = np.nan
        return xs, ys, zbuf.reshape(len(ys), len(xs))

    def _rasterise(self, zbuf, a, b, c, lo, hi, span: int, width: int, height: int) -> None:
        """Raise zbuf (flat H x W) to the triangles' (a, b, c: (T, 3) m) heights at the pixel centres
        they cover, over candidate pixels lo..hi (T, 2) of each, at most span x span per triangle."""
        x0, _, y0, _ = self.view
        off = np.arange(span)
        shape = (len(a), span, span)
        ix = np.broadcast_to(lo[:, 0, None, None] + off[None, None, :], shape)
        iy = np.broadcast_to(lo[:, 1, None, None] + off[None, :, None], shape)
        inside_box = (ix <= hi[:, 0, None, None]) & (iy <= hi[:, 1, None, None])
        inside_box &= (ix >= 0) & (ix < width) & (iy >= 0) & (iy < height)
        t, jy, jx = np.nonzero(inside_box)
        px, py = x0 + (ix[t, jy, jx] + 0.5) * self.pitch, y0 + (iy[t, jy, jx] + 0.5) * self.pitch
        # barycentric coordinates of the pixel centre in its triangle (top view)
        e1, e2 = (b - a)[t, :2], (c - a)[t, :2]
        det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
        ok = np.abs(det) > 1e-15
        rx, ry = px - a[t, 0], py - a[t, 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = (rx * e2[:, 1] - ry * e2[:, 0]) / det
            w = (e1[:, 0] * ry - e1[:, 1] * rx) / det
        ok &= (u >= -1e-12) & (w >= -1e-12) & (u + w <= 1 + 1e-12)
        z = (a[t, 2] + u * (b - a)[t, 2] + w * (c - a)[t, 2])[ok]
        pix = (iy[t, jy, jx] * width + ix[t, jy, jx])[ok]
        np.maximum.at(zbuf, pix, z)

    def cloud(self, vertices: np.ndarray, triangles: np.ndarray,
              rng: np.random.Generator | int | None = None) -> np.ndarray:
        """(P, 3) float64 points the camera returns for the cloth mesh (vertices (N, 3) m,
        triangles (M, 3)): visible top surface, noisy, with dropout."""
        return self._returns(vertices, triangles, np.random.default_rng(rng))[0]

    def colour_cloud(self, vertices: np.ndarray, triangles: np.ndarray,
                     rng: np.random.Generator | int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(points (P, 3) m, colours (P, 3) uint8): `cloud`'s points (the same for the same rng)
        and each one's colour, the cloth's or the table's, with noise."""
        rng = np.random.default_rng(rng)
        pts, on_cloth = self._returns(vertices, triangles, rng)
        rgb = np.where(on_cloth[:, None], np.asarray(self.cloth_rgb, float), np.asarray(self.table_rgb, float))
        rgb = rgb + rng.normal(0.0, self.colour_noise, rgb.shape) if self.colour_noise > 0 else rgb
        return pts, np.clip(np.rint(rgb), 0, 255).astype(np.uint8)

    def _returns(self, vertices: np.ndarray, triangles: np.ndarray,
                 rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """(points (P, 3) m, (P,) bool: the return is the cloth's, not the table's)."""
        xs, ys, z = self.height_map(vertices, triangles)
        gx, gy = np.meshgrid(xs, ys)
        hit = np.isfinite(z)
        cloth = hit.copy()
        if self.table:
            z = np.where(hit, z, 0.0)
            hit = np.ones_like(hit)
        pts = np.column_stack([gx[hit], gy[hit], z[hit]])
        on_cloth = cloth[hit]
        keep = rng.random(len(pts)) >= self.dropout
        pts, on_cloth = pts[keep], on_cloth[keep]
        pts[:, 2] += rng.normal(0.0, self.noise, len(pts)) if self.noise > 0 else 0.0
        return pts, on_cloth
