"""Pure geometry the 3D scene draws: robot links, the legs' workspace tori, the reachable volume.

No viser here: every function maps a robot (``RotaryDelta``, ``PerLegRotaryDelta`` whose
legs each have their own geometry, or ``LinearDelta``) and joint
values to NumPy arrays in the base frame [m], so the drawing is testable against the
kinematics. Conventions as everywhere: base frame, z up, the platform works at z < 0.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from app.control.model import Robot, leg_values
from kinematics import LinearDelta

LEG_ANGLES_RAD = (0.0, 2.0 * math.pi / 3.0, 4.0 * math.pi / 3.0)
ROD_SPACING_OF_R = 0.45  # parallelogram rod spacing as a share of the platform radius r


class RobotLines(NamedTuple):
    """Line segments of one pose, each (3 legs, 2 ends, 3) [m].

    upper: hip -> knee (rotary upper link; linear: rail reference -> carriage).
    rods: the parallelogram's two rods per leg, shape (3 legs, 2 rods, 2 ends, 3).
    """

    upper: np.ndarray
    rods: np.ndarray


class TorusSpec(NamedTuple):
    """One leg's workspace boundary as a torus (thesis Table 4.1), base frame.

    centre [m] (3,), axis (3,) unit vector of revolution, major_radius L [m] (circle of
    the shifted knee), tube_radius l [m] (the parallelogram). For a linear leg the
    boundary is a cylinder: ``major_radius`` 0, ``axis`` the rail direction.
    """

    centre: np.ndarray
    axis: np.ndarray
    major_radius: float
    tube_radius: float


def tangent(leg: int) -> np.ndarray:
    """Unit vector along leg ``leg``'s motor axis, -sin(a) x + cos(a) y (Table 4.1)."""
    a = LEG_ANGLES_RAD[leg]
    return np.array([-math.sin(a), math.cos(a), 0.0])


def radial(leg: int) -> np.ndarray:
    """Unit vector from the base centre towards leg ``leg``, (cos a, sin a, 0)."""
    a = LEG_ANGLES_RAD[leg]
    return np.array([math.cos(a), math.sin(a), 0.0])


def robot_lines(robot: Robot, joints_rad: Any) -> RobotLines:
    """Link segments for joints (3,) [rad or m]; NaN everywhere if FK fails."""
    hips, knees, ankles = robot.leg_points(np.asarray(joints_rad, dtype=np.float64))
    half = 0.5 * ROD_SPACING_OF_R * max(*leg_values(robot, "r"), 0.01)
    offsets = np.stack([tangent(i) * half for i in range(3)])[:, None, :]  # (3, 1, 3)
    upper = np.stack([hips, knees], axis=1)  # (3, 2, 3)
    rod_a = np.stack([knees + offsets[:, 0], ankles + offsets[:, 0]], axis=1)
    rod_b = np.stack([knees - offsets[:, 0], ankles - offsets[:, 0]], axis=1)
    return RobotLines(upper, np.stack([rod_a, rod_b], axis=1))


def torus_spec(robot: Robot, leg: int) -> TorusSpec:
    """Thesis Table 4.1 for leg ``leg``: centre Rbar (cos a, sin a, 0), axis, radii L and l
    (each leg's own, and its own base angle a, for a per-leg robot)."""
    if isinstance(robot, LinearDelta):
        rail = np.asarray(robot._rail(leg), dtype=np.float64)
        return TorusSpec(robot.Rbar * radial(leg), rail, 0.0, float(robot.l))
    a = getattr(robot, "angles_rad", LEG_ANGLES_RAD)[leg]
    Rbar = leg_values(robot, "R")[leg] - leg_values(robot, "r")[leg]
    centre = Rbar * np.array([math.cos(a), math.sin(a), 0.0])
    axis = np.array([-math.sin(a), math.cos(a), 0.0])
    return TorusSpec(centre, axis, leg_values(robot, "L")[leg], leg_values(robot, "l")[leg])


def _grid_faces(rows: int, cols: int) -> np.ndarray:
    """Two triangles per cell of a rows x cols vertex grid (not wrapped), (F, 3)."""
    r, c = np.meshgrid(np.arange(rows - 1), np.arange(cols - 1), indexing="ij")
    a = (r * cols + c).ravel()
    b, d = a + 1, a + cols
    return np.concatenate([np.stack([a, d, b], -1), np.stack([b, d, d + 1], -1)])


def _patch(spec: TorusSpec, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Torus surface points c + (L + l cos v) w(u) + l sin v n over the (u, v) grid."""
    n, e_z = spec.axis, np.array([0.0, 0.0, 1.0])
    e_r = np.cross(n, e_z)  # (cos a, sin a, 0) for n = (-sin a, cos a, 0)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    ring = spec.major_radius + spec.tube_radius * np.cos(vv)
    w = np.cos(uu)[..., None] * e_r + np.sin(uu)[..., None] * e_z
    points = spec.centre + ring[..., None] * w + (spec.tube_radius * np.sin(vv))[..., None] * n
    return points.reshape(-1, 3), _grid_faces(len(u), len(v))


def torus_lower_half(spec: TorusSpec, steps: int = 49) -> tuple[np.ndarray, np.ndarray]:
    """Lower half (z <= 0) of a spindle torus: outer 'apple' and inner 'lemon' surfaces.

    Returns vertices (V, 3) [m] and triangle faces (F, 3). Where L + l cos v >= 0 (the
    apple) z <= 0 needs sin u <= 0; on the lemon the sign flips, so each patch gets its own
    u range and the cut at z = 0 is exact rather than a jagged row of dropped faces. An
    odd ``steps`` puts a vertex on the lowest point, (L + l) below the centre.
    """
    v0 = math.acos(max(-1.0, -spec.major_radius / spec.tube_radius))
    apple = _patch(spec, np.linspace(math.pi, 2 * math.pi, steps), np.linspace(-v0, v0, steps))
    lemon_v = np.linspace(v0, 2 * math.pi - v0, max(steps // 2, 4))
    lemon = _patch(spec, np.linspace(0.0, math.pi, steps), lemon_v)
    vertices = np.concatenate([apple[0], lemon[0]])
    faces = np.concatenate([apple[1], lemon[1] + len(apple[0])])
    return vertices, faces


def cylinder_below(spec: TorusSpec, depth_m: float, steps: int = 48) -> tuple[np.ndarray, ...]:
    """A linear leg's boundary: cylinder of radius l about the rail, the part with z <= 0."""
    n = spec.axis / np.linalg.norm(spec.axis)
    helper = np.array([0.0, 0.0, 1.0]) if abs(n[2]) < 0.9 else radial(0)
    e1 = np.cross(n, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    t = np.linspace(-depth_m, depth_m, steps)
    angle = np.linspace(0.0, 2.0 * math.pi, steps)
    tt, aa = np.meshgrid(t, angle, indexing="ij")
    ring = np.cos(aa)[..., None] * e1 + np.sin(aa)[..., None] * e2
    points = spec.centre + tt[..., None] * n + spec.tube_radius * ring
    vertices, faces = points.reshape(-1, 3), _grid_faces(steps, steps)
    faces = faces[(vertices[faces][..., 2] <= 1e-9).all(axis=1)]
    used, faces = np.unique(faces, return_inverse=True)  # drop the vertices above the base
    return vertices[used], faces.reshape(-1, 3)


def torus_mesh(robot: Robot, leg: int) -> tuple[np.ndarray, np.ndarray]:
    """The lower half of leg ``leg``'s workspace boundary, vertices (V, 3) [m], faces (F, 3)."""
    spec = torus_spec(robot, leg)
    if isinstance(robot, LinearDelta):
        return cylinder_below(spec, depth_m=2.0 * robot.l + robot.R)
    return torus_lower_half(spec)
