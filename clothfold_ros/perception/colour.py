"""Telling the cloth from the table by colour, for clouds that hold the table too.

A real depth camera returns the table top as well as the cloth, and a cotton shirt (0.3 mm)
is far thinner than the camera's depth noise: no height threshold separates them. An RGB-D
camera's colour does, on a table of a colour unlike the shirt's. Colours are 8-bit RGB
(0-255); distances are Euclidean in that RGB cube. Pure numpy.
"""
from __future__ import annotations

import numpy as np

MAX_RGB_DISTANCE = float(np.sqrt(3.0) * 255.0)  # black to white


def unpack_rgb(packed: np.ndarray) -> np.ndarray:
    """(N, 3) uint8 RGB from PCL's packed colour: the 32 bits 0x00RRGGBB of each point's `rgb`
    (stored as float32) or `rgba` (uint32) field, given as uint32 (reinterpret float32 bits
    with `.view(np.uint32)` first)."""
    p = np.asarray(packed)
    if p.dtype != np.uint32:
        raise ValueError(f"packed colours must be uint32 (the field's bits), got {p.dtype}")
    return np.column_stack([(p >> 16) & 0xFF, (p >> 8) & 0xFF, p & 0xFF]).astype(np.uint8)


def pack_rgb(rgb: np.ndarray) -> np.ndarray:
    """(N,) uint32 0x00RRGGBB of (N, 3) colours in 0-255 (the inverse of `unpack_rgb`)."""
    c = np.asarray(rgb)
    if c.ndim != 2 or c.shape[1] != 3 or (c.size and (c.min() < 0 or c.max() > 255)):
        raise ValueError(f"colours must be (N, 3) values in 0..255, got shape {c.shape}")
    c = c.astype(np.uint32)
    return (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]


def off_table_colour(rgb: np.ndarray, table_rgb: np.ndarray | list[float], max_distance: float) -> np.ndarray:
    """(N,) bool: the points whose colour lies farther than `max_distance` from the table's
    colour (the cloth's, where the table's colour is unlike the shirt's)."""
    c = np.asarray(rgb, dtype=float)
    t = np.asarray(table_rgb, dtype=float).reshape(-1)
    if c.ndim != 2 or c.shape[1] != 3:
        raise ValueError(f"colours must be (N, 3), got shape {c.shape}")
    if t.shape != (3,) or not np.all((t >= 0) & (t <= 255)):
        raise ValueError(f"table colour must be 3 values in 0..255, got {t.tolist()}")
    if not 0.0 < max_distance <= MAX_RGB_DISTANCE:
        raise ValueError(f"colour distance must be in (0, {MAX_RGB_DISTANCE:.0f}], got {max_distance}")
    return np.linalg.norm(c - t, axis=1) > max_distance


def cloth_points(points: np.ndarray, rgb: np.ndarray, table_rgb: np.ndarray | list[float], max_distance: float,
                 config=None) -> np.ndarray:
    """The finite points (P, 3) of a cloud (N, 3) whose colour (N, 3) is not the table's. The
    cloud's share of NaN/inf points is judged on the whole cloud first (`estimator.finite_mask`:
    BadCloudError over `max_invalid_fraction`), as without the mask: dropping the table first
    would leave the shirt's few points beside all the invalid ones."""
    from .estimator import EstimatorConfig, finite_mask

    p = np.asarray(points, dtype=float)
    c = np.asarray(rgb)
    if len(c) != len(p):
        raise ValueError(f"{len(c)} colours for {len(p)} points")
    finite = finite_mask(p, config or EstimatorConfig())
    return p[finite & off_table_colour(c, table_rgb, max_distance)]
