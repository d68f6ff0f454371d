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
from typing import Any

import numpy as np
from scipy.optimize import minimize

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
    depth = robot.l + getattr(robot, "L", 0.0) + robot.R
    top = -1e-6 if z_max is None else min(z_max, -1e-6)
    z = np.linspace(top - 2.0 * depth, top, 801)
    candidates = np.stack([np.zeros_like(z), np.zeros_like(z), z], axis=-1)
    distances = signed_distance(robot, candidates)
    best = int(np.nanargmin(distances))
    return candidates[best], float(distances[best])


def _feasible(robot: Any, q: np.ndarray, margin: float, z_max: float | None) -> bool:
    # The IK's own test too: a boundary point must be one the IK accepts after rounding.
    inside = bool(signed_distance(robot, q) <= -margin) and bool(reachable(robot, q))
    return inside and (z_max is None or q[2] <= z_max)


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

    Args:
        point: goal in the base frame [m], shape (3,).
        margin: required distance from every leg's workspace boundary [m], >= 0.
        z_max: optional ceiling for the platform [m] (e.g. keep it below the base).

    Returns:
        Projection(point, distance). A reachable goal comes back unchanged.

    Raises:
        ShapeError / NonFiniteError: for a malformed goal.
        UnreachableError: when the margin leaves no reachable point at all.
    """
    goal = as_vectors(point, "point")
    if goal.shape != (3,):
        raise ShapeError(f"point: expected shape (3,), got {goal.shape}")
    if not np.isfinite(goal).all():
        raise NonFiniteError(f"point: must be finite, got {goal.tolist()}")
    if _feasible(robot, goal, margin, z_max):
        return Projection(goal.copy(), 0.0)
    anchor, depth = _anchor(robot, z_max)
    if not _feasible(robot, anchor, margin, z_max):
        raise UnreachableError(f"margin {margin} m leaves no reachable point (deepest {-depth} m)")
    start = _bisect(robot, anchor, goal, margin, z_max)
    best = _refine(robot, goal, start, margin, z_max)
    return Projection(best, float(np.linalg.norm(best - goal)))


def _refine(
    robot: Any, goal: np.ndarray, start: np.ndarray, margin: float, z_max: float | None
) -> np.ndarray:
    """Local least-distance solve from a feasible start; falls back to the start."""
    constraints = [
        {"type": "ineq", "fun": lambda q, i=i: -margin - robot._leg_signed_distance(i, *q)}
        for i in range(3)
    ]
    if z_max is not None:
        constraints.append({"type": "ineq", "fun": lambda q: z_max - q[2]})
    result = minimize(
        lambda q: float(np.sum((q - goal) ** 2)),
        start,
        jac=lambda q: 2.0 * (q - goal),
        constraints=constraints,
        method="SLSQP",
        options={"ftol": 1e-14, "maxiter": 200},
    )
    candidate = np.asarray(result.x, dtype=np.float64)
    if not np.isfinite(candidate).all():
        return start
    if not _feasible(robot, candidate, margin, z_max):
        candidate = _bisect(robot, start, candidate, margin, z_max)
    closer = np.linalg.norm(candidate - goal) < np.linalg.norm(start - goal)
    return candidate if closer else start
