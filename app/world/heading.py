"""The tool's heading in the world, and the wrist angle that gives it (hold-in-world, issue 19).

The heading of the tool is the world azimuth of its x axis: with the base turned by
``R`` (base to world, 3x3) and the wrist at ``phi`` [rad] about the platform's z (which
stays parallel to the base's z), the tool's x axis in the world is d = R Rz(phi) e_x and

    heading = atan2(d_y, d_x).

For a level base this is ``yaw + phi`` (``yaw`` the base's heading), so the wrist angle
that keeps a world heading h is ``phi = h - yaw``, wrapped; with the base tilted,
:func:`wrist_angle` solves the same condition exactly (the tool's x axis in the vertical
plane of azimuth h, pointing forward in it).
"""

from __future__ import annotations

import math

import numpy as np

TURN = 2.0 * math.pi


def wrap(angle_rad: float) -> float:
    """``angle_rad`` [rad] wrapped into [-pi, pi)."""
    return (float(angle_rad) + math.pi) % TURN - math.pi


def tool_heading(rotation: np.ndarray, phi_rad: float) -> float:
    """The world heading [rad] of the tool's x axis: base-to-world rotation ``rotation``
    (3, 3), wrist angle ``phi_rad`` [rad] (module docstring's equation)."""
    d = np.asarray(rotation, dtype=float) @ np.array([math.cos(phi_rad), math.sin(phi_rad), 0.0])
    return math.atan2(float(d[1]), float(d[0]))


def wrist_angle(rotation: np.ndarray, heading_rad: float) -> float:
    """The wrist angle phi in [-pi, pi] [rad] whose tool x axis has world heading
    ``heading_rad`` [rad] with the base turned by ``rotation`` (3, 3), i.e. the inverse of
    :func:`tool_heading` in phi. The x axis u = (cos phi, sin phi, 0) must be normal to the
    world's n = (-sin h, cos h, 0), so u is normal to m = R^T n in the base's xy plane, and
    points forward (R u . (cos h, sin h, 0) > 0)."""
    r = np.asarray(rotation, dtype=float)
    h = float(heading_rad)
    m = r.T @ np.array([-math.sin(h), math.cos(h), 0.0])
    forward = r.T @ np.array([math.cos(h), math.sin(h), 0.0])
    u = np.array([m[1], -m[0]])
    if float(u @ forward[:2]) < 0.0:
        u = -u
    return math.atan2(float(u[1]), float(u[0]))


def fit_to_limits(phi_rad: float, low_rad: float, high_rad: float, near_rad: float):
    """``phi_rad`` [rad] moved by whole turns into the wrist's limits [low, high] [rad],
    the candidate nearest ``near_rad`` (the angle the wrist is at) when two fit; if none
    does, the limit nearest it round the circle. Returns (phi [rad], limited: bool)."""
    base = wrap(phi_rad)
    fits = [base + k * TURN for k in (-2, -1, 0, 1, 2) if low_rad <= base + k * TURN <= high_rad]
    if fits:
        return min(fits, key=lambda p: abs(p - near_rad)), False
    nearest = min((low_rad, high_rad), key=lambda limit: abs(wrap(base - limit)))
    return nearest, True
