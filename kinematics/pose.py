"""Rigid poses for the drone-mounted Delta (thesis ch. 5.1, eq. 5.1-5.2).

A pose is a position and a unit quaternion (w, x, y, z), Hamilton convention, mapping
body coordinates to world coordinates: p_world = position + R(q) p_body. The Delta's
base sits on the drone through a fixed mount pose (base in the drone's body frame), so

    T_world_base = T_world_drone @ T_drone_base
    goal_base    = R_wb^T (goal_world - t_wb)                       (eq. 5.1-5.2)

Poses broadcast: positions (*, 3) and quaternions (*, 4) describe a batch of poses.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ._arrays import as_vectors
from .errors import PoseError

UNIT_TOLERANCE = 1e-3
"""Largest | |q| - 1 | that is treated as drift and normalised; beyond it, rejected."""


def unit_quaternion(
    value: Any, name: str = "quaternion", tol: float = UNIT_TOLERANCE
) -> np.ndarray:
    """Validate and normalise quaternions (w, x, y, z), shape (*, 4).

    Raises:
        PoseError: non-finite values, a zero quaternion, or a norm off 1 by more than tol.
    """
    q = as_vectors(value, name, size=4)
    if not np.isfinite(q).all():
        raise PoseError(f"{name}: must be finite, got {q.tolist()}")
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(norm == 0.0):
        raise PoseError(f"{name}: the zero quaternion is not a rotation")
    drift = np.abs(norm - 1.0)
    if np.any(drift > tol):
        raise PoseError(
            f"{name}: not a unit quaternion (|q| = {float(norm.flat[np.argmax(drift)]):.6g}, "
            f"tolerance {tol})"
        )
    return q / norm


def quaternion_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (*, 3, 3) of unit quaternions (*, 4) (w, x, y, z)."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    rows = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    return np.stack([np.stack(row, -1) for row in rows], -2)


def quaternion_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a * b of quaternions (*, 4)."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        -1,
    )


@dataclass(frozen=True, eq=False)
class Pose:
    """Body-to-world rigid transform. Build with :meth:`from_arrays` to validate input."""

    position: np.ndarray  # (*, 3) [m]
    quaternion: np.ndarray  # (*, 4) unit, (w, x, y, z)

    @classmethod
    def from_arrays(cls, position: Any, quaternion: Any = (1.0, 0.0, 0.0, 0.0)) -> Pose:
        """Validated pose: finite position [m], unit quaternion (small drift normalised)."""
        p = as_vectors(position, "position")
        if not np.isfinite(p).all():
            raise PoseError(f"position: must be finite, got {p.tolist()}")
        return cls(p, unit_quaternion(quaternion))

    @classmethod
    def identity(cls) -> Pose:
        return cls(np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]))

    @property
    def rotation(self) -> np.ndarray:
        """Rotation matrix (*, 3, 3), body to world."""
        return quaternion_to_matrix(self.quaternion)

    def __matmul__(self, other: Pose) -> Pose:
        """Composition: (self @ other) maps other's body frame through self to world."""
        position = self.apply(other.position)
        return Pose(position, quaternion_multiply(self.quaternion, other.quaternion))

    def inverse(self) -> Pose:
        conjugate = self.quaternion * np.array([1.0, -1.0, -1.0, -1.0])
        position = -np.einsum("...ji,...j->...i", self.rotation, self.position)
        return Pose(position, conjugate)

    def apply(self, points: Any) -> np.ndarray:
        """Body coordinates (*, 3) to world coordinates [m]."""
        p = as_vectors(points, "points")
        return np.einsum("...ij,...j->...i", self.rotation, p) + self.position

    def apply_inverse(self, points: Any) -> np.ndarray:
        """World coordinates (*, 3) to body coordinates [m]."""
        p = as_vectors(points, "points")
        return np.einsum("...ji,...j->...i", self.rotation, p - self.position)


def world_to_base(goal_world: Any, drone: Pose, mount: Pose | None = None) -> np.ndarray:
    """Goal in the Delta's base frame from a world goal and the drone pose (eq. 5.1-5.2).

    Args:
        goal_world: points in the world frame [m], shape (*, 3).
        drone: drone body pose in the world (position, quaternion body to world).
        mount: the Delta base's pose in the drone body frame (identity if None).
    """
    base = drone if mount is None else drone @ mount
    return base.apply_inverse(goal_world)


def base_to_world(points_base: Any, drone: Pose, mount: Pose | None = None) -> np.ndarray:
    """Points in the base frame [m], (*, 3), to the world frame."""
    base = drone if mount is None else drone @ mount
    return base.apply(points_base)
