"""Gripper grasp box (method section "Grasp") and the grasp springs that hold the cloth.

The box is centred on the gripper pose: 5 cm along the gripper x axis (world up), 12 cm
along y (across the approach) and 5 cm along z (the approach direction). Every triangle
with a vertex in the box is grasped with all three of its vertices, through every layer
of a stack (what a gripper sliding under the cloth from the side holds).

Held vertices are attached to grip points fixed in the gripper frame by stiff springs
(see ClothSimulator.step), not pinned: where the gripper motion would force held cloth
into other cloth or the table, contact wins and the held cloth lags; cloth that lags
more than the slip distance slips in the grip (its grip point moves to where it is).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..pose import Pose

GRASP_BOX = np.array([0.05, 0.12, 0.05])  # m, extent along gripper x, y, z


@dataclass(frozen=True)
class Grasp:
    """Vertices held by one gripper and their grip points in the gripper frame."""

    vertex_ids: np.ndarray  # (K,) int
    local: np.ndarray  # (K, 3) m, gripper frame

    def targets(self, pose: Pose) -> np.ndarray:
        """Grip points (K, 3), table frame, for a gripper at `pose`."""
        return pose.transform_points(self.local)

    def slipped(self, pose: Pose, x: np.ndarray, mask: np.ndarray) -> "Grasp":
        """The grasp after the vertices `mask` (K,) slipped to their positions x (N, 3)."""
        local = self.local.copy()
        local[mask] = (x[self.vertex_ids[mask]] - pose.position) @ pose.matrix
        return Grasp(self.vertex_ids, local)


def grasp(x: np.ndarray, triangles: np.ndarray, pose: Pose, box: np.ndarray = GRASP_BOX) -> Grasp:
    """Grasp the cloth at positions x (N, 3) with a gripper at `pose`.

    Raises ValueError when the box holds no cloth vertex.
    """
    local = (x - pose.position) @ pose.matrix  # coordinates in the gripper frame
    inside = np.all(np.abs(local) <= 0.5 * np.asarray(box), axis=1)
    if not inside.any():
        raise ValueError(f"grasp at {np.round(pose.position, 4).tolist()} m holds no cloth vertex")
    tri_hit = inside[triangles].any(axis=1)
    ids = np.unique(triangles[tri_hit])
    return Grasp(vertex_ids=ids, local=local[ids])
