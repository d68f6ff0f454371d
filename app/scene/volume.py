"""The reachable volume as a surface mesh: marching cubes on the workspace's signed distance.

The field is max(signed_distance + margin, z - z_max): the gate's own workspace (margin
from every leg's boundary, below the ceiling), so the surface drawn is where jog goals
are clamped to. A coarse pass finds the volume's bounding box, a fine pass meshes it.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from skimage.measure import marching_cubes

from app.control.model import Robot, reach_m
from kinematics import LinearDelta


class VolumeMesh(NamedTuple):
    """Triangle mesh [m]: vertices (V, 3), faces (F, 3); spacing_m: the grid step used."""

    vertices: np.ndarray
    faces: np.ndarray
    spacing_m: float


def floor_m(robot: Robot, z_max_m: float) -> float | None:
    """Lowest z drawn [m]: a linear Delta's volume is unbounded downwards, so cut it one
    parallelogram length below the ceiling; a rotary one closes by itself (None)."""
    return z_max_m - robot.l - robot.R if isinstance(robot, LinearDelta) else None


def volume_field(robot: Robot, points: np.ndarray, margin_m: float, z_max_m: float) -> np.ndarray:
    """<= 0 where the gate accepts a point (workspace with margin, below z_max) [m].

    points: (*, 3) [m]. For a linear Delta the drawn floor (see floor_m) closes it.
    """
    field = np.maximum(robot.signed_distance(points) + margin_m, points[..., 2] - z_max_m)
    floor = floor_m(robot, z_max_m)
    return field if floor is None else np.maximum(field, floor - points[..., 2])


def _extent(robot: Robot) -> float:
    """A length [m] beyond which nothing is reachable in x, y (and depth for rotary)."""
    return reach_m(robot)


def _grid(lo: np.ndarray, hi: np.ndarray, step: float) -> tuple[np.ndarray, tuple[int, ...]]:
    axes = [np.arange(a, b + step, step) for a, b in zip(lo, hi, strict=True)]
    mesh = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    return mesh, mesh.shape[:3]


def _bounds(robot, margin_m: float, z_max_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Bounding box of the accepted volume from a coarse grid, padded by one coarse step."""
    extent = _extent(robot)
    floor = floor_m(robot, z_max_m)
    lo = np.array([-extent, -extent, z_max_m - 2.0 * extent if floor is None else floor])
    hi = np.array([extent, extent, z_max_m])
    step = (hi - lo).max() / 40.0
    points, _ = _grid(lo, hi, step)
    inside = volume_field(robot, points, margin_m, z_max_m) <= 0.0
    if not inside.any():
        raise ValueError("the workspace is empty with this margin and ceiling")
    found = points[inside]
    return np.maximum(found.min(0) - step, lo), np.minimum(found.max(0) + step, hi)


def reachable_volume(
    robot: Robot, margin_m: float, z_max_m: float, step_m: float = 0.006
) -> VolumeMesh:
    """Closed surface of the accepted volume, vertices on the boundary to about step_m / 10."""
    lo, hi = _bounds(robot, margin_m, z_max_m)
    points, shape = _grid(lo, hi, step_m)
    field = volume_field(robot, points.reshape(-1, 3), margin_m, z_max_m).reshape(shape)
    # Outside the box counts as outside, so the surface closes where the box cuts it.
    padded = np.pad(field, 1, constant_values=step_m)
    padded = np.where(np.isfinite(padded), padded, step_m)
    vertices, faces, _, _ = marching_cubes(padded, level=0.0, spacing=(step_m,) * 3)
    vertices = _onto_surface(robot, vertices + (lo - step_m), margin_m, z_max_m, step_m)
    return VolumeMesh(vertices, faces.astype(np.int64), step_m)


def _onto_surface(robot, vertices: np.ndarray, margin_m: float, z_max_m: float, step_m: float):
    """Newton steps along the field's gradient: marching cubes cuts the creases where two
    tori meet by up to step/4; this puts vertices back on the boundary (gate-exact)."""
    h = 1e-5
    v = vertices.astype(np.float64)
    for _ in range(3):
        f = volume_field(robot, v, margin_m, z_max_m)
        grad = np.stack(
            [(volume_field(robot, v + h * e, margin_m, z_max_m) - f) / h for e in np.eye(3)],
            axis=-1,
        )
        norm2 = np.maximum(np.sum(grad * grad, axis=-1), 1e-12)
        move = -(f / norm2)[:, None] * grad
        # Never further than a grid step: a bad gradient must not throw a vertex away.
        length = np.linalg.norm(move, axis=-1, keepdims=True)
        v = v + move * np.minimum(1.0, step_m / np.maximum(length, 1e-300))
    return v
