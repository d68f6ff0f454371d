"""Workspace analysis: reachable volume, largest box or cylinder, section maps.

Numbers only (figures are drawn by app/design). The largest box (or cylinder) of given
proportions at a given height is found by bisection on its scale, each candidate
certified by :mod:`containment`: boxes sharing a centre (or a top-face centre) are
nested, so containment is monotone in the scale and bisection is exact to its step.
"""

from __future__ import annotations

from typing import Any, Literal, NamedTuple

import numpy as np

from ._arrays import triple_floats
from .containment import certify_box, certify_cylinder


class Volume(NamedTuple):
    """Reachable volume [m^3] below ``z_max`` by counting grid cells, with the cell size [m]
    and the volume of cells on the boundary (an error bound on the count) [m^3]."""

    volume_m3: float
    cell_m: float
    boundary_m3: float


def reach_bounds(robot: Any) -> tuple[np.ndarray, np.ndarray]:
    """A box [m] that holds the whole workspace: |P - hip| <= L + l."""
    reach = getattr(robot, "L", 0.0) + robot.l + robot.R
    return np.array([-reach, -reach, -reach]), np.array([reach, reach, reach])


def workspace_volume(robot: Any, cells_per_axis: int = 120, z_max: float = 0.0) -> Volume:
    """Volume of the reachable set below z_max [m] (thesis: the lower half, z < 0).

    Counts cell centres on a regular grid (chunked by z-layer to bound memory).
    """
    lower, upper = reach_bounds(robot)
    upper[2] = min(upper[2], z_max)
    cell = (upper - lower) / cells_per_axis
    axes = [lower[k] + (np.arange(cells_per_axis) + 0.5) * cell[k] for k in range(3)]
    x, y = np.meshgrid(axes[0], axes[1], indexing="ij")
    inside = boundary = 0
    for z in axes[2]:
        layer = np.stack([x, y, np.full_like(x, z)], -1)
        distance = robot.signed_distance(layer)
        inside += int((distance <= 0).sum())
        # a cell whose centre is within half a diagonal of the boundary may be split
        boundary += int((np.abs(distance) <= 0.5 * np.linalg.norm(cell)).sum())
    dv = float(np.prod(cell))
    return Volume(inside * dv, float(cell.max()), boundary * dv)


class Fit(NamedTuple):
    """A largest region: its size [m] (box edges x, y, z, or cylinder diameter and
    height), its bounds [m] (lower, upper corners of the box or bounding box), and the
    scale step left by the bisection [m]."""

    size_m: tuple[float, float, float]
    lower: tuple[float, float, float]
    upper: tuple[float, float, float]
    resolution_m: float


def largest_region(
    robot: Any,
    proportions: tuple[float, float, float] = (1.0, 1.0, 1.0),
    z: float = -0.25,
    anchor: Literal["centre", "top"] = "centre",
    shape: Literal["box", "cylinder"] = "box",
    tol: float = 1e-5,
    resolution_m: float = 1e-4,
) -> Fit:
    """Largest box (edges proportional to ``proportions``) or vertical cylinder
    (diameter : height = proportions[0] : proportions[2]) on the z axis in the workspace.

    Args:
        z: height of the centre, or of the top face with anchor="top" [m].
        tol: accepted overhang in the certification [m]; a candidate the octree cannot
            decide within its budget counts as not fitting (the answer errs small).
        resolution_m: bisection stops when the largest edge is known to this [m].
    """
    ratio = np.asarray(proportions, float) / max(proportions)

    def bounds(scale: float) -> tuple[np.ndarray, np.ndarray]:
        size = scale * ratio
        top = z + size[2] / 2 if anchor == "centre" else z
        return np.array([-size[0] / 2, -size[1] / 2, top - size[2]]), np.array(
            [size[0] / 2, size[1] / 2, top]
        )

    def fits(scale: float) -> bool:
        lo, hi = bounds(scale)
        if shape == "cylinder":
            verdict = certify_cylinder(robot, hi[0], lo[2], hi[2], tol=tol)
        else:
            verdict = certify_box(robot, lo, hi, tol=tol)
        return verdict.contains is True

    good, bad = 0.0, 2.0 * float(np.max(reach_bounds(robot)[1]))
    if not fits(1e-9):
        return Fit((0.0, 0.0, 0.0), (0.0, 0.0, z), (0.0, 0.0, z), 0.0)
    while bad - good > resolution_m:
        middle = 0.5 * (good + bad)
        good, bad = (middle, bad) if fits(middle) else (good, middle)
    lo, hi = bounds(good)
    size = triple_floats(good * ratio, "size_m")
    return Fit(size, tuple(lo.tolist()), tuple(hi.tolist()), float(bad - good))


class Section(NamedTuple):
    """A planar section of the workspace on a grid.

    u, v: grid coordinates [m], each (n,); plane: "xy" (at z = level) or "xz"/"yz";
    points: (n, n, 3) [m]; dexterity: 1/cond(J) (NaN outside), (n, n);
    power_of_point: sum_i |h_i| (thesis Fig. 4.5) [m^4], (n, n); reachable: (n, n).
    """

    plane: str
    level: float
    u: np.ndarray
    v: np.ndarray
    points: np.ndarray
    dexterity: np.ndarray
    power_of_point: np.ndarray
    reachable: np.ndarray


def section(
    robot: Any,
    plane: Literal["xy", "xz", "yz"] = "xy",
    level: float = -0.25,
    extent: tuple[float, float, float, float] | None = None,
    n: int = 121,
) -> Section:
    """Dexterity and power-of-point maps over a section (thesis Fig. 4.2-4.5 style).

    Args:
        plane: "xy" at z = level; "xz" at y = level; "yz" at x = level [m].
        extent: (u_min, u_max, v_min, v_max) [m]; default covers the reach.
        n: grid points per axis.
    """
    lower, upper = reach_bounds(robot)
    if extent is None:
        vmin = lower[2] if plane != "xy" else lower[1]
        vmax = 0.0 if plane != "xy" else upper[1]
        extent = (lower[0], upper[0], vmin, vmax)
    u, v = np.linspace(extent[0], extent[1], n), np.linspace(extent[2], extent[3], n)
    uu, vv = np.meshgrid(u, v, indexing="xy")
    flat = np.full_like(uu, level)
    columns = {"xy": (uu, vv, flat), "xz": (uu, flat, vv), "yz": (flat, uu, vv)}[plane]
    points = np.stack(columns, -1)
    ik = robot.ik(points)
    dexterity = np.where(ik.ok, robot.dexterity(ik.joints), np.nan)
    power = np.abs(robot.h(points)).sum(-1)
    return Section(plane, level, u, v, points, dexterity, power, ik.ok)
