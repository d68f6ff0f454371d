"""Certified containment of a box in a Delta's workspace.

The workspace is not convex (each leg's region is a spindle torus minus its inner
lemon), so a box whose eight vertices are reachable may still poke out along an edge or
hide a hole. Sampling alone cannot prove otherwise; a Lipschitz bound can.

``robot.signed_distance`` is the largest of the legs' (nearest-circle distance - l,
l - farthest-circle distance): each a distance function minus a constant, so the maximum
is 1-Lipschitz, and it is <= 0 exactly where every leg reaches. Hence if a cell with
centre c and half-diagonal d has sd(c) + d <= tol, every point of the cell is within
``tol`` of the workspace; if sd(c) > 0, c itself is a reachable-free witness. Cells
that are neither are split in eight. Once d < tol every cell is decided, so the octree
below always answers (or stops at its cell budget and says so).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from ._arrays import as_vectors

_CORNERS = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)


class Containment(NamedTuple):
    """Answer of :func:`certify_box`.

    contains: True (certified), False (``witness`` is outside), or None (cell budget
        exhausted before a decision).
    witness: a point of the box outside the workspace [m], shape (3,), or None.
    worst_m: the largest signed distance met at a cell centre [m] (> 0: outside by).
    cells: how many cells were evaluated.
    """

    contains: bool | None
    witness: np.ndarray | None
    worst_m: float
    cells: int


def certify_box(
    robot: Any, lower: Any, upper: Any, tol: float = 1e-4, max_cells: int = 2_000_000
) -> Containment:
    """Decide whether the axis-aligned box [lower, upper] [m] lies in the workspace.

    Args:
        robot: a Delta with ``signed_distance``.
        lower, upper: opposite corners [m], shape (3,).
        tol: accepted overhang [m]: "contains" means every point of the box is within
            ``tol`` of a reachable point. A box touching the boundary (as an optimum
            does) can only be certified with tol > 0.
        max_cells: evaluation budget.

    Returns:
        Containment. Finds every outside region larger than the finest cells; a miss
        would need an outside sliver thinner than ~tol.
    """
    lo, hi = as_vectors(lower, "lower"), as_vectors(upper, "upper")
    return _certify(robot, lo, hi, lambda c: np.clip(c, lo, hi), tol, max_cells)


def certify_cylinder(
    robot: Any,
    radius: float,
    z_low: float,
    z_high: float,
    tol: float = 1e-4,
    max_cells: int = 2_000_000,
) -> Containment:
    """:func:`certify_box` for a vertical cylinder on the z axis, radius and z range [m]."""

    def nearest(c: np.ndarray) -> np.ndarray:
        rho = np.hypot(c[:, 0], c[:, 1])
        shrink = np.where(rho > radius, radius / np.maximum(rho, 1e-300), 1.0)[:, None]
        return np.concatenate([c[:, :2] * shrink, np.clip(c[:, 2:], z_low, z_high)], -1)

    lo, hi = np.array([-radius, -radius, z_low]), np.array([radius, radius, z_high])
    return _certify(robot, lo, hi, nearest, tol, max_cells)


def _first_cells(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Near-cubic starting cells over [lo, hi]: centres (n, 3) and one half-size (3,)."""
    half = 0.5 * (hi - lo)
    shortest = half[half > 0].min() if (half > 0).any() else 1.0  # a flat box is fine
    counts = np.maximum(1, np.round(half / shortest)).astype(int)
    grids = [(np.arange(n) + 0.5) / n * 2.0 - 1.0 for n in counts]
    offsets = np.stack(np.meshgrid(*grids, indexing="ij"), -1).reshape(-1, 3)
    return 0.5 * (lo + hi) + offsets * half, half / counts


def _certify(
    robot: Any, lo: np.ndarray, hi: np.ndarray, nearest: Any, tol: float, max_cells: int
) -> Containment:
    """Octree over [lo, hi] for the region whose nearest point to c is nearest(c).

    Each cell is judged at x, the region's point nearest its centre c: if |x - c| > d
    the cell misses the region; if sd(x) > 0, x is a witness; if sd(x) + |x - c| + d
    <= tol, every point of the cell is within tol of the workspace (1-Lipschitz).
    """
    centres, half = _first_cells(lo, hi)
    evaluated, worst = 0, -np.inf
    while len(centres):
        evaluated += len(centres)
        if evaluated > max_cells:
            return Containment(None, None, float(worst), evaluated)
        radius = float(np.linalg.norm(half))
        probe = nearest(centres)
        offset = np.linalg.norm(probe - centres, axis=-1)
        meets = offset <= radius * (1 + 1e-12)
        probe, centres, offset = probe[meets], centres[meets], offset[meets]
        distance = robot.signed_distance(probe)
        distance = np.where(np.isfinite(distance), distance, np.inf)
        worst = max(worst, float(distance.max(initial=-np.inf)))
        if (distance > 0.0).any():
            return Containment(False, probe[int(np.argmax(distance))], worst, evaluated)
        open_cells = distance + offset + radius > tol
        half = half / 2.0
        centres = (centres[open_cells][:, None, :] + _CORNERS * half).reshape(-1, 3)
    return Containment(True, None, float(worst), evaluated)


def box_samples(lower: Any, upper: Any, per_edge: int = 9) -> np.ndarray:
    """Points on a box's faces (a ``per_edge`` grid on each) and a coarse interior grid.

    Returns: shape (K, 3) [m]. For penalties during a search; :func:`certify_box` decides.
    """
    lo, hi = as_vectors(lower, "lower"), as_vectors(upper, "upper")
    return lo + unit_box_samples(per_edge) * (hi - lo)


def unit_box_samples(per_edge: int = 9) -> np.ndarray:
    """:func:`box_samples` of the unit cube [0, 1]^3, shape (K, 3)."""
    t = np.linspace(0.0, 1.0, per_edge)
    grid = np.stack(np.meshgrid(t, t, t, indexing="ij"), -1).reshape(-1, 3)
    on_face = ((grid == 0.0) | (grid == 1.0)).any(-1)
    inner = np.linspace(0.25, 0.75, 3)
    interior = np.stack(np.meshgrid(inner, inner, inner, indexing="ij"), -1).reshape(-1, 3)
    return np.concatenate([grid[on_face], interior])
