"""The reachable volume as a surface mesh: marching cubes on the workspace's signed distance.

The field is max(signed_distance + margin, z - z_max): the gate's own workspace (margin
from every leg's boundary, below the ceiling), so the surface drawn is where jog goals
are clamped to. A coarse pass finds the volume's bounding box, a fine pass meshes it.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from skimage.measure import marching_cubes

from kinematics import LinearDelta, RotaryDelta


class VolumeMesh(NamedTuple):
    """Triangle mesh [m]: vertices (V, 3), faces (F, 3); spacing_m: the grid step used."""

    vertices: np.ndarray
    faces: np.ndarray
    spacing_m: float


def volume_field(
    robot: RotaryDelta | LinearDelta, points: np.ndarray, margin_m: float, z_max_m: float
) -> np.ndarray:
    """<= 0 where the gate accepts a point (workspace with margin, below z_max) [m]."""
    distance = robot.signed_distance(points) + margin_m
    return np.maximum(distance, points[..., 2] - z_max_m)


def _extent(robot: RotaryDelta | LinearDelta) -> float:
    """A length [m] beyond which nothing is reachable in x, y (and depth for rotary)."""
    return robot.R + getattr(robot, "L", 0.0) + robot.l


def _grid(lo: np.ndarray, hi: np.ndarray, step: float) -> tuple[np.ndarray, tuple[int, ...]]:
    axes = [np.arange(a, b + step, step) for a, b in zip(lo, hi, strict=True)]
    mesh = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    return mesh, mesh.shape[:3]


def _bounds(robot, margin_m: float, z_max_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Bounding box of the accepted volume from a coarse grid, padded by one coarse step."""
    extent = _extent(robot)
    # A linear Delta's volume is unbounded downwards: show one parallelogram length of it.
    depth = 2.0 * extent if isinstance(robot, RotaryDelta) else robot.l + robot.R
    lo = np.array([-extent, -extent, z_max_m - depth])
    hi = np.array([extent, extent, z_max_m])
    step = (hi - lo).max() / 40.0
    points, _ = _grid(lo, hi, step)
    inside = volume_field(robot, points, margin_m, z_max_m) <= 0.0
    if not inside.any():
        raise ValueError("the workspace is empty with this margin and ceiling")
    found = points[inside]
    return np.maximum(found.min(0) - step, lo), np.minimum(found.max(0) + step, hi)


def reachable_volume(
    robot: RotaryDelta | LinearDelta, margin_m: float, z_max_m: float, step_m: float = 0.006
) -> VolumeMesh:
    """Closed surface of the accepted volume, vertices on the boundary to about step_m / 10."""
    lo, hi = _bounds(robot, margin_m, z_max_m)
    points, shape = _grid(lo, hi, step_m)
    field = volume_field(robot, points.reshape(-1, 3), margin_m, z_max_m).reshape(shape)
    # Outside the box counts as outside, so the surface closes where the box cuts it.
    padded = np.pad(field, 1, constant_values=step_m)
    padded = np.where(np.isfinite(padded), padded, step_m)
    vertices, faces, _, _ = marching_cubes(padded, level=0.0, spacing=(step_m,) * 3)
    vertices = vertices + (lo - step_m)
    return VolumeMesh(vertices.astype(np.float64), faces.astype(np.int64), step_m)
