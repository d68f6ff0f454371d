"""Per-leg workspace of a rotary Delta as functions of its geometry (thesis eq. 4.1-4.4).

Vectorized over designs as well as points, for the synthesis's population: the same
formulas as RotaryDelta's h and signed distance, with L, l, Rbar as arrays.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ._xp import LEG_COS, LEG_SIN

_COS, _SIN = np.array(LEG_COS), np.array(LEG_SIN)


def _columns(L: Any, l: Any, Rbar: Any, points: Any) -> tuple:
    L, l, Rbar = (np.asarray(v, float)[..., None, None] for v in (L, l, Rbar))
    p = np.asarray(points, float)
    return L, l, Rbar, p[..., 0, None], p[..., 1, None], p[..., 2, None]


def torus_h(L: Any, l: Any, Rbar: Any, points: Any) -> np.ndarray:
    """Per-leg torus functions h_i (eq. 4.2), <= 0 where leg i reaches [m^4].

    Args:
        L, l, Rbar: geometry [m], shape (*S) (one value per design).
        points: shape (*S, K, 3) or (K, 3) [m].

    Returns:
        shape (*S, K, 3 legs).
    """
    L, l, Rbar, x, y, z = _columns(L, l, Rbar, points)
    along = x * _COS + y * _SIN  # (*S, K, 3 legs)
    E = 2.0 * L * (Rbar - along)
    F = 2.0 * L * z
    G = x * x + y * y + z * z + Rbar * Rbar + L * L - l * l - 2.0 * Rbar * along
    return G * G - E * E - F * F


def torus_distance(L: Any, l: Any, Rbar: Any, points: Any) -> np.ndarray:
    """Per-leg signed distance to the reach boundary [m], negative inside.

    Same shapes as :func:`torus_h`; equal to RotaryDelta's per-leg signed distance: the
    sphere of radius l about P must meet the knee circle (radius L about the motor axis).
    """
    L, l, Rbar, x, y, z = _columns(L, l, Rbar, points)
    radial = x * _COS + y * _SIN - Rbar
    axial = -x * _SIN + y * _COS
    rho = np.hypot(radial, z)
    nearest, farthest = np.hypot(rho - L, axial), np.hypot(rho + L, axial)
    return np.maximum(nearest - l, l - farthest)


def torus_inside(L: Any, l: Any, Rbar: Any, points: Any, clearance: float = 0.0) -> np.ndarray:
    """True where leg i reaches with ``clearance`` [m] to spare: torus_distance <= -clearance.

    The same test on squared distances, one square root instead of three (the synthesis
    calls it for every design and sample of every generation).
    """
    L, l, Rbar, x, y, z = _columns(L, l, Rbar, points)
    radial = x * _COS + y * _SIN - Rbar
    axial_sq = (-x * _SIN + y * _COS) ** 2
    rho = np.sqrt(radial * radial + z * z)
    near_ok = (rho - L) ** 2 + axial_sq <= (l - clearance) ** 2
    far_ok = (rho + L) ** 2 + axial_sq >= (l + clearance) ** 2
    return near_ok & far_ok & (l > clearance)
