"""Small meshes and helpers for simulator tests."""
from __future__ import annotations

import ipctk
import numpy as np
import triangle


def rectangle(width: float, height: float, max_area: float, z: float, origin=(0.0, 0.0)):
    """A flat rectangle mesh (vertices (N, 3) m, triangles (M, 3)) at height z."""
    ox, oy = origin
    pts = np.array([[ox, oy], [ox + width, oy], [ox + width, oy + height], [ox, oy + height]], float)
    seg = np.array([[0, 1], [1, 2], [2, 3], [3, 0]])
    t = triangle.triangulate({"vertices": pts, "segments": seg}, f"pq30a{max_area:.8f}")
    v = np.column_stack([t["vertices"], np.full(len(t["vertices"]), z)])
    return v, t["triangles"].astype(np.int64)


def intersection_free(sim) -> bool:
    """Independent check: no self-intersection and nothing below the table top."""
    x = np.asfortranarray(sim.x)
    return (not ipctk.has_intersections(sim.contact.mesh, x)) and bool(np.all(sim.x[:, 2] > 0.0))


def edge_strain(rest: np.ndarray, x: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Relative length change of every mesh edge."""
    e = ipctk.edges(triangles.astype(np.int32))
    l0 = np.linalg.norm(rest[e[:, 0]] - rest[e[:, 1]], axis=1)
    l1 = np.linalg.norm(x[e[:, 0]] - x[e[:, 1]], axis=1)
    return l1 / l0 - 1.0
