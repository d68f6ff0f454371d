"""Closed-form intersection of three spheres: the forward kinematics.

Both Delta types reduce their FK to the same problem (thesis ch. 3.1.1, paper eq. 12):
the platform centre lies at distance ``l`` from the three (radially shifted) knee
points. Subtracting the sphere equations gives two planes; their line passes
through the circumcentre ``q0`` of the knee triangle along its normal ``n``:

    P = C1 + q0 + t n,   t = -sign(n_z) sqrt((l^2 - |q0|^2) / |n|^2)

With unequal radii l1, l2, l3 (a per-leg model) the planes move: with a = C2 - C1,
b = C3 - C1, the point q0 of the triangle's plane has q0 . a = (|a|^2 + l1^2 - l2^2) / 2
and q0 . b = (|b|^2 + l1^2 - l3^2) / 2, and l1 replaces l in t. Equal radii add an
exact 0.0, so the symmetric robot's answers do not change by a bit.

The sign picks the solution below the knee plane (the platform hangs below the base).
No iteration, no cancellation-prone 'solve z first' step.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ._xp import ARRAYS, FLOATS

Columns = tuple[Any, Any, Any]


Radii = float | tuple[float, float, float]


def _lower_intersection(c1: Columns, c2: Columns, c3: Columns, radii: Radii, xp: Any) -> Columns:
    """The formula, on NumPy columns or Python floats alike (see _xp)."""
    if isinstance(radii, tuple):
        radius = radii[0]
        d2, d3 = radius * radius - radii[1] * radii[1], radius * radius - radii[2] * radii[2]
    else:
        radius, d2, d3 = radii, 0.0, 0.0
    ax, ay, az = c2[0] - c1[0], c2[1] - c1[1], c2[2] - c1[2]
    bx, by, bz = c3[0] - c1[0], c3[1] - c1[1], c3[2] - c1[2]
    nx = ay * bz - az * by
    ny = az * bx - ax * bz
    nz = ax * by - ay * bx
    n2 = nx * nx + ny * ny + nz * nz
    ha = 0.5 * (ax * ax + ay * ay + az * az + d2) / n2
    hb = 0.5 * (bx * bx + by * by + bz * bz + d3) / n2
    # circumcentre of the triangle (0, a, b) (equal radii): ha (b x n) + hb (n x a)
    qx = ha * (by * nz - bz * ny) + hb * (ny * az - nz * ay)
    qy = ha * (bz * nx - bx * nz) + hb * (nz * ax - nx * az)
    qz = ha * (bx * ny - by * nx) + hb * (nx * ay - ny * ax)
    t = -xp.copysign(xp.sqrt((radius * radius - (qx * qx + qy * qy + qz * qz)) / n2), nz)
    return c1[0] + qx + t * nx, c1[1] + qy + t * ny, c1[2] + qz + t * nz


def intersect_below(c1: Columns, c2: Columns, c3: Columns, radius: Radii) -> Columns:
    """Lower intersection of three spheres, in columns (x, y, z) of shape (n,).

    Args:
        c1, c2, c3: sphere centres as (x, y, z) column arrays [m], each shape (n,).
        radius: common sphere radius [m], or the three radii (l1, l2, l3) [m].

    Returns:
        (x, y, z) of the intersection [m]; NaN where the spheres do not meet or the
        centres are collinear.
    """
    with np.errstate(invalid="ignore", divide="ignore"):
        return _lower_intersection(c1, c2, c3, radius, ARRAYS)


def intersect_below_point(
    c1: tuple[float, float, float],
    c2: tuple[float, float, float],
    c3: tuple[float, float, float],
    radius: Radii,
) -> tuple[float, float, float]:
    """Scalar twin of :func:`intersect_below` on Python floats (NaN if no intersection)."""
    try:
        return _lower_intersection(c1, c2, c3, radius, FLOATS)
    except ZeroDivisionError:
        return math.nan, math.nan, math.nan
