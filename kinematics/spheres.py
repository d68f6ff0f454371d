"""Closed-form intersection of three spheres of equal radius: the forward kinematics.

Both Delta types reduce their FK to the same problem (thesis ch. 3.1.1, paper eq. 12):
the platform centre lies at distance ``l`` from the three (radially shifted) knee
points. Subtracting the sphere equations gives two planes; their line passes
through the circumcentre ``q0`` of the knee triangle along its normal ``n``:

    P = C1 + q0 + t n,   t = -sign(n_z) sqrt((l^2 - |q0|^2) / |n|^2)

The sign picks the solution below the knee plane (the platform hangs below the base).
No iteration, no cancellation-prone 'solve z first' step.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ._xp import ARRAYS, FLOATS

Columns = tuple[Any, Any, Any]


def _lower_intersection(c1: Columns, c2: Columns, c3: Columns, radius: float, xp: Any) -> Columns:
    """The formula, on NumPy columns or Python floats alike (see _xp)."""
    ax, ay, az = c2[0] - c1[0], c2[1] - c1[1], c2[2] - c1[2]
    bx, by, bz = c3[0] - c1[0], c3[1] - c1[1], c3[2] - c1[2]
    nx = ay * bz - az * by
    ny = az * bx - ax * bz
    nz = ax * by - ay * bx
    n2 = nx * nx + ny * ny + nz * nz
    ha = 0.5 * (ax * ax + ay * ay + az * az) / n2
    hb = 0.5 * (bx * bx + by * by + bz * bz) / n2
    # circumcentre of the triangle (0, a, b): ha (b x n) + hb (n x a)
    qx = ha * (by * nz - bz * ny) + hb * (ny * az - nz * ay)
    qy = ha * (bz * nx - bx * nz) + hb * (nz * ax - nx * az)
    qz = ha * (bx * ny - by * nx) + hb * (nx * ay - ny * ax)
    t = -xp.copysign(xp.sqrt((radius * radius - (qx * qx + qy * qy + qz * qz)) / n2), nz)
    return c1[0] + qx + t * nx, c1[1] + qy + t * ny, c1[2] + qz + t * nz


def intersect_below(c1: Columns, c2: Columns, c3: Columns, radius: float) -> Columns:
    """Lower intersection of three spheres, in columns (x, y, z) of shape (n,).

    Args:
        c1, c2, c3: sphere centres as (x, y, z) column arrays [m], each shape (n,).
        radius: common sphere radius [m].

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
    radius: float,
) -> tuple[float, float, float]:
    """Scalar twin of :func:`intersect_below` on Python floats (NaN if no intersection)."""
    try:
        return _lower_intersection(c1, c2, c3, radius, FLOATS)
    except ZeroDivisionError:
        return math.nan, math.nan, math.nan
