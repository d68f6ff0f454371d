"""The workspace: per-leg torus functions, reachability, distance and projection.

Leg i reaches P exactly where its IK discriminant is non-negative; thesis eq. 4.1-4.2
write this as h_i = G_i^2 - E_i^2 - F_i^2 <= 0 (the printed '+ F^2' is a slip). For a
rotary leg that is a spindle torus about the motor axis (major radius L, tube radius l)
minus its inner lemon; for a linear leg a cylinder of radius l about the rail.

h is a quartic [m^4] (or quadratic [m^2]); for margins and projection the module uses
the per-leg Euclidean distance to the boundary [m] instead.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np

from . import projection
from ._arrays import as_vectors
from .errors import NonFiniteError, ShapeError, UnreachableError
from .results import Projection


def h(robot: Any, points: Any) -> np.ndarray:
    """Per-leg workspace functions (thesis eq. 4.2): <= 0 inside, shape (*, 3)."""
    p = as_vectors(points, "points")
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    with np.errstate(all="ignore"):
        return np.stack([-robot._leg_discriminant(i, x, y, z) for i in range(3)], -1)


def signed_distance(robot: Any, points: Any) -> np.ndarray:
    """Distance [m] to the workspace boundary, negative inside, shape (*).

    The largest of the three legs' exact distances: exact outside one leg's boundary,
    and a lower bound on the depth inside, so ``<= -margin`` keeps a margin from all.
    """
    p = as_vectors(points, "points")
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    with np.errstate(all="ignore"):
        legs = [robot._leg_signed_distance(i, x, y, z) for i in range(3)]
    return np.maximum(np.maximum(legs[0], legs[1]), legs[2])


def reachable(robot: Any, points: Any, margin: float = 0.0) -> np.ndarray:
    """True where the platform centre can reach ``points`` (shape (*)).

    With ``margin`` > 0 [m], only points at least that far inside every leg's boundary.
    Non-finite points are not reachable. margin = 0 agrees exactly with ``ik(...).ok``.
    """
    p = as_vectors(points, "points")
    finite = np.isfinite(p).all(axis=-1)
    if margin == 0.0:
        with np.errstate(invalid="ignore"):
            return finite & (h(robot, p) <= 0.0).all(axis=-1)
    return finite & (signed_distance(robot, p) <= -margin)


@functools.lru_cache(maxsize=64)
def _anchor(robot: Any, z_max: float | None) -> tuple[np.ndarray, float]:
    """Deepest point on the z axis below ``z_max``: a start that is inside if anything is."""
    # per-leg robots (kinematics/per_leg.py) have three of each: the longest reach counts
    depth = float(np.max(robot.l) + np.max(getattr(robot, "L", 0.0)) + np.max(robot.R))
    top = -1e-6 if z_max is None else min(z_max, -1e-6)
    z = np.linspace(top - 2.0 * depth, top, 801)
    candidates = np.stack([np.zeros_like(z), np.zeros_like(z), z], axis=-1)
    distances = signed_distance(robot, candidates)
    best = int(np.nanargmin(distances))
    return candidates[best], float(distances[best])


def _feasible(robot: Any, q: np.ndarray, margin: float, z_max: float | None) -> bool:
    """One point: every leg at least ``margin`` inside, the IK accepts it, below ``z_max``."""
    x, y, z = (float(v) for v in q)
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        return False
    if z_max is not None and not z <= z_max:
        return False
    if not all(robot._leg_signed_distance(i, x, y, z) <= -margin for i in range(3)):
        return False
    return bool(robot.ik((x, y, z)).ok)  # the IK's own test: what the caller will run


def _bisect(
    robot: Any, inside: np.ndarray, outside: np.ndarray, margin: float, z_max: float | None
) -> np.ndarray:
    for _ in range(60):
        middle = 0.5 * (inside + outside)
        if _feasible(robot, middle, margin, z_max):
            inside = middle
        else:
            outside = middle
    return inside


def project(robot: Any, point: Any, margin: float = 0.0, z_max: float | None = None) -> Projection:
    """Nearest point to ``point`` that is reachable with ``margin`` [m] to spare.

    How: the admissible set (every leg reaches with ``margin`` to spare, i.e.
    ``signed_distance <= -margin``, and z <= ``z_max``) is bounded by faces (one leg's
    tube or lemon, a linear leg's cylinder, or the ceiling), edges where two meet and
    vertices where three do. The answer is the nearest admissible one of: the critical
    points of the distance on every face (closed form: the nearest point of a knee
    circle, then along the tube), the vertices, and the local minima along the edges
    (Newton's method from the cached edge samples that bracket one and could beat the
    best so far). Vertical rails reduce to three discs in x, y: exact. See
    :mod:`kinematics.projection`; the first call for a (robot, margin, z_max) samples
    the edges (0.1-0.5 s), later calls cost about 0.1-0.6 ms (docs/performance.md).

    Guarantee: the answer is admissible (the IK's own test, the margin, the ceiling),
    and no admissible point is nearer the goal by more than 0.1 mm. Face and vertex
    answers are exact to ~1e-9 m; an edge's minimum is found wherever two neighbouring
    samples (a few mm apart) bracket it, i.e. unless the edge turns back within one
    sample gap. Tested as a law against dense samples on random robots and goals.

    Args:
        point: goal in the base frame [m], shape (3,).
        margin: required distance from every leg's workspace boundary [m], >= 0.
        z_max: optional ceiling for the platform [m] (e.g. keep it below the base).

    Returns:
        Projection(point, distance). An admissible goal comes back unchanged.

    Raises:
        ShapeError / NonFiniteError: for a malformed goal.
        UnreachableError: when the margin (and ceiling) leave no reachable point at all.
    """
    goal = as_vectors(point, "point")
    if goal.shape != (3,):
        raise ShapeError(f"point: expected shape (3,), got {goal.shape}")
    if not np.isfinite(goal).all():
        raise NonFiniteError(f"point: must be finite, got {goal.tolist()}")
    if _feasible(robot, goal, margin, z_max):
        return Projection(goal.copy(), 0.0)
    best = projection.nearest(robot, goal, margin, z_max)
    if best is None or not _feasible(robot, best, margin, z_max):
        anchor, depth = _anchor(robot, z_max)
        if not _feasible(robot, anchor, margin, z_max):
            raise UnreachableError(
                f"margin {margin} m leaves no reachable point (deepest {-depth} m)"
            )
        best = _bisect(robot, anchor, goal if best is None else best, margin, z_max)
    return Projection(best, float(np.linalg.norm(best - goal)))
