"""Rigid gripper poses: position (m, table frame) + unit quaternion (x, y, z, w, ROS order)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp


@dataclass(frozen=True)
class Pose:
    """A pose in the table frame. `quaternion` is (x, y, z, w) like geometry_msgs."""

    position: np.ndarray
    quaternion: np.ndarray

    def __post_init__(self) -> None:
        p, q = np.asarray(self.position, dtype=float), np.asarray(self.quaternion, dtype=float)
        if p.size != 3 or q.size != 4:
            raise ValueError(f"pose needs a 3-vector position and a 4-vector quaternion, got sizes {p.size} and {q.size}")
        p, q = p.reshape(3), q.reshape(4)
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(q))):
            raise ValueError(f"pose has non-finite values: position={p}, quaternion={q}")
        scale = np.max(np.abs(q))  # normalised in two steps: a norm of huge components overflows to inf
        if not scale > 0 or np.linalg.norm(q / scale) * scale < 1e-9:
            raise ValueError("pose quaternion has zero norm")
        q = q / scale
        object.__setattr__(self, "position", p)
        object.__setattr__(self, "quaternion", q / np.linalg.norm(q))

    @property
    def rotation(self) -> Rotation:
        return Rotation.from_quat(self.quaternion)

    @property
    def matrix(self) -> np.ndarray:
        """3x3 rotation matrix; columns are the gripper x, y, z axes in the table frame."""
        return self.rotation.as_matrix()

    @classmethod
    def from_axes(cls, position: np.ndarray, x_axis: np.ndarray, z_axis: np.ndarray) -> "Pose":
        """Pose from its x and z axes (orthonormalised; y = z cross x)."""
        x = np.asarray(x_axis, float)
        if not (np.all(np.isfinite(x)) and np.linalg.norm(x) > 1e-12):
            raise ValueError(f"gripper x axis must be finite and non-zero, got {x}")
        x = x / np.linalg.norm(x)
        z = np.asarray(z_axis, float)
        if not (z.shape == (3,) and np.all(np.isfinite(z))):
            raise ValueError(f"gripper z axis must be a finite 3-vector, got {z}")
        z = z - x * (x @ z)
        nz = np.linalg.norm(z)
        if nz < 1e-9:
            raise ValueError("gripper x and z axes are parallel")
        z = z / nz
        y = np.cross(z, x)
        return cls(position, Rotation.from_matrix(np.column_stack([x, y, z])).as_quat())

    def transform_points(self, points_local: np.ndarray) -> np.ndarray:
        """Map (N, 3) points from the gripper frame to the table frame."""
        return np.asarray(points_local) @ self.matrix.T + self.position


def slerp(a: Pose, b: Pose, u: np.ndarray | float) -> np.ndarray:
    """Quaternions (x, y, z, w) interpolated from a (u = 0) to b (u = 1); shape (..., 4)."""
    u_arr = np.clip(np.asarray(u, dtype=float), 0.0, 1.0)
    s = Slerp([0.0, 1.0], Rotation.from_quat(np.stack([a.quaternion, b.quaternion])))
    return s(u_arr.ravel()).as_quat().reshape(u_arr.shape + (4,))
