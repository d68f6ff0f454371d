"""Planar sections of the gate's workspace, for the page's 2D view (no WebGL needed).

A section is a regular grid on a plane, each cell centre marked where the gate accepts a
goal there (app/control/gate.py ``Gate.inside``: every leg's boundary at least the margin
away, i.e. the intersection of the three legs' tori shrunk by the margin, and below the
ceiling). The grid's extent is the accepted volume's bounding box (same for every level, so
the view's scale does not jump as the platform moves), its step about 1/160 of the largest
side. Sections are cached per (gate, plane, level rounded to 1 mm): the page asks again
only when the platform has moved a few millimetres.
"""

from __future__ import annotations

import functools
from typing import Literal, NamedTuple

import numpy as np

from app.control.gate import Gate

Plane = Literal["xy", "xz", "yz"]
AXES: dict[str, tuple[int, int, int]] = {"xy": (0, 1, 2), "xz": (0, 2, 1), "yz": (1, 2, 0)}
"""plane -> (index of u, index of v, index of the level's axis) in (x, y, z)."""
CELLS = 160  # along the longest side of the extent
LEVEL_STEP_M = 1e-3  # levels are rounded to this (the cache key)


class Section(NamedTuple):
    """One section: ``reachable[j, i]`` is whether (u_m[i], v_m[j]) at ``level_m`` passes.

    plane: "xy" (level is z), "xz" (level is y) or "yz" (level is x); u_m (n_u,), v_m (n_v,)
    cell centres [m]; reachable (n_v, n_u) bool; level_m: the level used [m] (rounded).
    """

    plane: str
    level_m: float
    u_m: np.ndarray
    v_m: np.ndarray
    reachable: np.ndarray


def accepted(gate: Gate, points: np.ndarray) -> np.ndarray:
    """``Gate.inside`` for many points: (*, 3) [m] -> (*) bool (vectorised, same rule)."""
    points = np.asarray(points, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        below = points[..., 2] <= gate.z_max_m
    return below & gate.robot.reachable(points, margin=gate.margin_m)


@functools.lru_cache(maxsize=8)
def extent(gate: Gate) -> tuple[np.ndarray, np.ndarray]:
    """The accepted volume's bounding box (lower (3,), upper (3,)) [m], from a 60^3 grid,
    padded by one of its steps (so the ceiling shows too); ValueError if nothing is accepted."""
    reach = gate.robot.R + getattr(gate.robot, "L", 0.0) + gate.robot.l
    top = min(gate.z_max_m, 0.0)
    lower = np.array([-reach, -reach, top - 2.0 * reach])
    upper = np.array([reach, reach, top])
    axes = [np.linspace(lower[k], upper[k], 60) for k in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    inside = accepted(gate, grid)
    if not inside.any():
        raise ValueError("the workspace is empty with this margin and ceiling")
    step = (upper - lower) / 59
    found = grid[inside]
    return found.min(0) - step, found.max(0) + step  # a frame of refused cells all round


def rounded_level(level_m: float) -> float:
    """The level a section is computed at [m]: ``level_m`` rounded to LEVEL_STEP_M."""
    return round(round(level_m / LEVEL_STEP_M) * LEVEL_STEP_M, 6)


def section(gate: Gate, plane: Plane, level_m: float) -> Section:
    """The accepted region on ``plane`` at ``level_m`` [m] (rounded, see rounded_level).

    Raises KeyError for an unknown plane. Cached per (gate, plane, rounded level).
    """
    return _section(gate, plane, rounded_level(level_m))


@functools.lru_cache(maxsize=64)
def _section(gate: Gate, plane: str, level_m: float) -> Section:
    iu, iv, il = AXES[plane]
    lower, upper = extent(gate)
    cell = float((upper - lower).max()) / CELLS
    u = np.arange(lower[iu] + cell / 2, upper[iu], cell)
    v = np.arange(lower[iv] + cell / 2, upper[iv], cell)
    uu, vv = np.meshgrid(u, v, indexing="xy")
    points = np.empty((*uu.shape, 3))
    points[..., iu], points[..., iv], points[..., il] = uu, vv, level_m
    inside = accepted(gate, points)
    for array in (u, v, inside):
        array.flags.writeable = False  # shared by every caller of the cache
    return Section(plane, level_m, u, v, inside)
