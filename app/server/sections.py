"""Planar sections of the gate's workspace, for the page's 2D view (no WebGL needed).

A section is a regular grid on a plane, each cell centre marked where the gate accepts a
goal there (app/control/gate.py: ``Gate.inside``, every leg's boundary at least the margin
away, i.e. the intersection of the three legs' tori shrunk by the margin, and below the
ceiling; then the joint limits and the singularity margin on the IK's knee-out branch, see
:func:`accepted`). The workspace alone is not enough: at z = -240 mm its nearest point to
(300, 20) mm needs joint 2 at 118 deg, beyond its 94.5 deg limit, and the gate refuses it.
The grid's extent is the workspace's bounding box (same for every level and, with a
wrist, every wrist angle, so the view's scale does not jump as the platform moves or the
tool turns), its step about 1/160 of the largest side. Points are tool tips at a wrist angle
phi (the gate checks the platform centre each implies): with a tool off the wrist's axis
the accepted region moves as the wrist turns. Sections are cached per (gate, plane, level
rounded to 1 mm, phi rounded to 1 deg): the page asks again only when the platform has
moved a few millimetres or the wrist turned by a degree.
"""

from __future__ import annotations

import functools
from typing import Literal, NamedTuple

import numpy as np

from app.control.gate import FAR_M, Gate
from app.control.model import reach_m

Plane = Literal["xy", "xz", "yz"]
AXES: dict[str, tuple[int, int, int]] = {"xy": (0, 1, 2), "xz": (0, 2, 1), "yz": (1, 2, 0)}
"""plane -> (index of u, index of v, index of the level's axis) in (x, y, z)."""
CELLS = 160  # along the longest side of the extent
LEVEL_STEP_M = 1e-3  # levels are rounded to this (the cache key)
PHI_STEP_RAD = np.pi / 180  # and wrist angles to this
NUDGE_M = 2e-5  # a nearest point is moved this far inwards: 0.01 mm rounding stays inside


class Section(NamedTuple):
    """One section: ``reachable[j, i]`` is whether (u_m[i], v_m[j]) at ``level_m`` passes.

    plane: "xy" (level is z), "xz" (level is y) or "yz" (level is x); u_m (n_u,), v_m (n_v,)
    cell centres [m]; reachable (n_v, n_u) bool; level_m: the level used [m] (rounded);
    phi_rad: the wrist angle used [rad] (rounded).
    """

    plane: str
    level_m: float
    u_m: np.ndarray
    v_m: np.ndarray
    reachable: np.ndarray
    phi_rad: float = 0.0


def inside(gate: Gate, points: np.ndarray, phi: float = 0.0) -> np.ndarray:
    """``Gate.inside`` for many tool tips at wrist angle ``phi`` [rad]: (*, 3) [m] -> (*)
    bool (vectorised, same rule, on the platform centre each tip implies)."""
    platform = gate.platform(np.asarray(points, dtype=np.float64), phi)
    with np.errstate(invalid="ignore"):
        below = platform[..., 2] <= gate.z_max_m
    return below & gate.robot.reachable(platform, margin=gate.margin_m)


def accepted(gate: Gate, points: np.ndarray, phi: float = 0.0) -> np.ndarray:
    """Whether the gate accepts each tip as a goal at wrist angle ``phi`` [rad] from a
    working posture: (*, 3) [m] -> (*) bool. ``inside`` (margin, ceiling), then the IK's
    knee-out branch (the one ``Gate.solve`` falls back on) within the joint limits and at
    least ``min_dexterity`` from a singularity, as ``Gate.check_joints`` judges one point."""
    points = np.asarray(points, dtype=np.float64)
    ok = inside(gate, points, phi)
    if not ok.any():
        return ok
    solution = gate.robot.ik(gate.platform(points[ok], phi))
    joints = solution.joints
    low, high = np.array(gate.joint_min_rad), np.array(gate.joint_max_rad)
    with np.errstate(invalid="ignore"):
        limits = ((joints >= low) & (joints <= high)).all(axis=-1)
        dexterity = np.asarray(gate.robot.dexterity(joints))
        ok[ok] = solution.ok & limits & (dexterity >= gate.min_dexterity)
    return ok


@functools.lru_cache(maxsize=64)
def anchor(gate: Gate, phi: float = 0.0) -> np.ndarray:
    """An accepted tip at wrist angle ``phi`` [rad] whose platform centre is on the z axis,
    deepest inside the workspace (3,) [m]: where :func:`nearest` heads when the workspace's
    nearest point breaks a joint limit."""
    lower, upper = extent(gate)
    platform = np.zeros((400, 3))
    platform[:, 2] = np.linspace(lower[2], upper[2], 400) - gate.tip(np.zeros(3), phi)[2]
    column = gate.tip(platform, phi)
    good = accepted(gate, column, phi)
    if not good.any():
        raise ValueError("the gate accepts no point on the z axis")
    depth = np.where(good, -gate.robot.signed_distance(platform), -np.inf)
    return column[int(np.argmax(depth))]


def nearest(gate: Gate, point: np.ndarray, phi: float = 0.0, samples: int = 100) -> np.ndarray:
    """A tip the gate accepts at wrist angle ``phi`` [rad] near ``point`` (3,) [m]
    (``point`` itself if accepted): the page's "go to nearest" and the 422's ``nearest_m``.

    The gate refuses a goal outside the workspace (margin, ceiling), beyond a joint limit
    or too near a singularity (:func:`accepted`); the nearest accepted point is the
    Euclidean projection onto that set, found in three steps:

    1. a start: the workspace's nearest point (``Gate.nearest``) if accepted, else the
       accepted point nearest it on the segment to :func:`anchor` (``samples`` steps,
       then bisection);
    2. shells: the workspace's distance d_ws is a lower bound and the start's an upper
       one; bisect the radius r, asking whether any of SHELL_POINTS directions at r from
       ``point`` is accepted (to SHELL_TOL_M), keeping the accepted point found;
    3. a pattern search around it: PATTERN_POINTS directions at a step that halves
       from PATTERN_STEP_M to PATTERN_END_M, moving to the closest accepted point that
       is nearer ``point``.

    Sampled, so not provably the nearest: on the thesis's Delta it is within 1 mm of the
    nearest accepted point of a 2 mm grid (tests/app/server/test_nearest.py). The point
    is then moved NUDGE_M towards the anchor (when that is accepted too), so that rounded
    to 0.01 mm, as a page shows and sends it, it is still accepted. Every point returned
    passed :func:`accepted`. Cost: tens to a few hundred ms (call it off the event loop).
    """
    point = np.asarray(point, dtype=np.float64)
    if accepted(gate, point[None], phi)[0]:
        return point
    home = anchor(gate, phi)
    projected = gate.nearest(point, phi)
    found = projected
    if not accepted(gate, found[None], phi)[0]:
        found = _towards(gate, found, home, samples, phi)
    if float(np.abs(point).max()) <= FAR_M:  # beyond, the shells would lose precision
        found = _refine(gate, point, found, float(np.linalg.norm(projected - point)), phi)
    length = float(np.linalg.norm(home - found))
    nudged = found + (home - found) * min(NUDGE_M / length, 1.0) if length > 0 else found
    return nudged if accepted(gate, nudged[None], phi)[0] else found


SHELL_POINTS = 1000
SHELL_TOL_M = 5e-4
PATTERN_POINTS = 32
PATTERN_STEP_M = 4e-3
PATTERN_END_M = 2e-5


def _directions(n: int) -> np.ndarray:
    """``n`` unit vectors spread evenly over the sphere (a Fibonacci lattice), (n, 3)."""
    i = np.arange(n) + 0.5
    polar = np.arccos(1.0 - 2.0 * i / n)
    azimuth = np.pi * (1.0 + 5.0**0.5) * i
    return np.stack(
        [np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar), np.cos(polar)], -1
    )


def _refine(
    gate: Gate, point: np.ndarray, found: np.ndarray, lower_m: float, phi: float
) -> np.ndarray:
    """An accepted point no farther from ``point`` than ``found`` (accepted), steps 2 and 3
    of :func:`nearest`; ``lower_m``: no accepted point is nearer than this [m]."""
    best, high = found, float(np.linalg.norm(found - point))
    shell = _directions(SHELL_POINTS)
    low = min(lower_m, high)
    while high - low > SHELL_TOL_M:
        middle = 0.5 * (low + high)
        candidates = point + middle * shell
        ok = accepted(gate, candidates, phi)
        if ok.any():
            best, high = candidates[int(np.argmax(ok))], middle
        else:
            low = middle
    pattern = _directions(PATTERN_POINTS)
    step = PATTERN_STEP_M
    while step > PATTERN_END_M:
        candidates = best + step * pattern
        distance = np.linalg.norm(candidates - point, axis=1)
        ok = (distance < high) & accepted(gate, candidates, phi)
        if ok.any():
            k = int(np.flatnonzero(ok)[np.argmin(distance[ok])])
            best, high = candidates[k], float(distance[k])
        else:
            step *= 0.5
    return best


def _towards(
    gate: Gate, start: np.ndarray, home: np.ndarray, samples: int, phi: float
) -> np.ndarray:
    """The accepted point nearest ``start`` on the segment to ``home`` (which is accepted)."""
    steps = np.linspace(0.0, 1.0, samples + 1)
    line = start + steps[:, None] * (home - start)
    first = int(np.argmax(accepted(gate, line, phi)))
    bad, good = steps[max(first - 1, 0)], steps[first]
    for _ in range(20):
        middle = 0.5 * (bad + good)
        if accepted(gate, (start + middle * (home - start))[None], phi)[0]:
            good = middle
        else:
            bad = middle
    return start + good * (home - start)


@functools.lru_cache(maxsize=8)
def extent(gate: Gate) -> tuple[np.ndarray, np.ndarray]:
    """The accepted volume's bounding box (lower (3,), upper (3,)) [m], from a 60^3 grid,
    padded by one of its steps (so the ceiling shows too); ValueError if nothing is accepted.
    Tool tips: the platform's box moved by the tool offset; with a wrist, the box of every
    wrist angle (the platform's widened by the offset's sideways length: the tip circles the
    platform centre as the wrist turns)."""
    reach = reach_m(gate.robot)
    top = min(gate.z_max_m, 0.0)
    offset = gate.tip(np.zeros(3))
    lower = np.array([-reach, -reach, top - 2.0 * reach]) + offset
    upper = np.array([reach, reach, top]) + offset
    axes = [np.linspace(lower[k], upper[k], 60) for k in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    found_inside = inside(gate, grid)
    if not found_inside.any():
        raise ValueError("the workspace is empty with this margin and ceiling")
    step = (upper - lower) / 59
    found = grid[found_inside]
    low, high = found.min(0) - step, found.max(0) + step  # a frame of refused cells all round
    if gate.wrist_min_rad is not None:  # every angle: the platform's box, widened
        sideways = float(np.hypot(offset[0], offset[1]))
        low[:2] += -offset[:2] - sideways
        high[:2] += -offset[:2] + sideways
    return low, high


def rounded_level(level_m: float) -> float:
    """The level a section is computed at [m]: ``level_m`` rounded to LEVEL_STEP_M."""
    return round(round(level_m / LEVEL_STEP_M) * LEVEL_STEP_M, 6)


def rounded_phi(phi_rad: float) -> float:
    """The wrist angle a section is computed at [rad]: ``phi_rad`` rounded to PHI_STEP_RAD."""
    return round(round(phi_rad / PHI_STEP_RAD) * PHI_STEP_RAD, 9)


def section(gate: Gate, plane: Plane, level_m: float, phi: float = 0.0) -> Section:
    """The accepted region on ``plane`` at ``level_m`` [m] for tips at wrist angle ``phi``
    [rad] (both rounded, see rounded_level and rounded_phi).

    Raises KeyError for an unknown plane. Cached per (gate, plane, rounded level and phi).
    """
    return _section(gate, plane, rounded_level(level_m), rounded_phi(phi))


@functools.lru_cache(maxsize=256)
def _section(gate: Gate, plane: str, level_m: float, phi: float = 0.0) -> Section:
    iu, iv, il = AXES[plane]
    lower, upper = extent(gate)
    cell = float((upper - lower).max()) / CELLS
    u = np.arange(lower[iu] + cell / 2, upper[iu], cell)
    v = np.arange(lower[iv] + cell / 2, upper[iv], cell)
    uu, vv = np.meshgrid(u, v, indexing="xy")
    points = np.empty((*uu.shape, 3))
    points[..., iu], points[..., iv], points[..., il] = uu, vv, level_m
    ok = accepted(gate, points, phi)
    for array in (u, v, ok):
        array.flags.writeable = False  # shared by every caller of the cache
    return Section(plane, level_m, u, v, ok, phi)
