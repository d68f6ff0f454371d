"""The nearest admissible point: projection onto the workspace with a margin and a ceiling.

The admissible set is A = {p : every leg reaches p with ``margin`` m to spare, p_z <= z_max},
the intersection of three per-leg sets and a half-space. Each is written as constraints
c_k(p) <= 0 where every c_k is a distance [m] (1-Lipschitz):

- rotary leg i, knee circle K_i (radius L about motor axis i, see ``RotaryDelta``), with
  dn / df the distances from p to its nearest / farthest point: the tube
  c = dn - (l - margin) (a spindle torus) and the lemon c = (l + margin) - df (the hole
  about the motor axis where the rod cannot fold back far enough);
- linear leg i: the cylinder c = dist(p, rail i) - (l - margin);
- the ceiling c = p_z - z_max.

A goal g outside A has its nearest point p* on A's boundary, which is made of faces (one
constraint active), edges (two) and vertices (three); p* is a local minimum of |p - g|
on the face or edge it lies on, or a vertex. So the candidates are:

- faces: the only local minimum of |p - g| on a tube lies on the line from the nearest
  point of the knee circle to g, at the tube's radius (for a cylinder: on the radial line
  from the rail); on a lemon, the critical points are on the lines from the nearest or
  farthest knee-circle point: at most 16 points, in closed form;
- vertices: solved once per (robot, margin, z_max) by Newton's method and cached;
- edges: sampled once and cached (a grid on every surface, each sign change of another
  constraint between grid neighbours moved onto the edge by Gauss-Newton, then halved
  twice), each sample linked to the next one along its edge. Per query, a link whose
  ends see the distance fall then rise brackets a local minimum, whose distance is at
  least (f_i + f_j - link) / 2 (the distance is 1-Lipschitz); brackets whose bound beats
  the best candidate so far are solved by Newton's method on the edge's optimality
  condition c_a = c_b = 0, (g - p).(grad c_a x grad c_b) = 0, best bound first.

The nearest admissible candidate is the answer. Everything is solved on constraints
tightened by ``EPS`` m, so a boundary answer passes the IK's own test after rounding.
Vertical rails (all parallel) reduce to three discs in x, y and are solved exactly.

What it guarantees: the answer is admissible; face and vertex answers are exact (~1e-9 m).
An edge's local minimum is found when a link brackets it; one hidden by the edge bending
back within a link (a few mm), or beyond the 12 lowest-bound brackets (ties, as for a
goal at the centre of a circular edge), could be missed. The laws of
tests/kinematics/test_projection.py (nothing admissible nearer by more than 0.1 mm) held
on ~900 random robots, margins, ceilings and goals, and a multi-start SLSQP oracle found
nothing nearer on ~500 more. Rails within a few degrees of vertical (but not vertical)
make a long admissible set: its sampling gets coarser (links of 16 mm at 88 deg).
"""

from __future__ import annotations

import functools
import math
from typing import Any, NamedTuple

import numpy as np

from ._xp import LEG_ANGLES_RAD, LEG_COS, LEG_SIN

EPS = 1e-9
"""Constraints are solved this much tighter [m], so a boundary answer is strictly inside."""

_ADMIT = 1e-11  # slack [m] on a tightened constraint when testing a candidate
_Z = np.array([0.0, 0.0, 1.0])
_U = np.array([[c, s, 0.0] for c, s in zip(LEG_COS, LEG_SIN, strict=True)])  # radial
_A = np.array([[-s, c, 0.0] for c, s in zip(LEG_COS, LEG_SIN, strict=True)])  # motor axes
_CELL = 0.012  # grid cell [m] on each surface when looking for edges (at most l / 20)
_GRID_POINTS = 20_000  # at most this many grid points per surface (larger robots: coarser)
_FD = 1e-7  # forward-difference step [m] of the Newton solve along an edge
# Edge solves per query at most: more are due only where many tie (a goal at the centre
# of a circular edge, all of whose points are about as near).
_MOST_SOLVES = 12


class Constraints(NamedTuple):
    """The constraints c_k(p) <= 0 of one (robot, margin, z_max), tightened by EPS.

    kind: "rotary" or "linear"; Rbar: R - r [m]; axes (3, 3): motor axes or rail
    directions; L: upper link [m] (0 for linear); tube: l - margin - EPS [m]; lemon:
    l + margin + EPS [m]; top: z_max - EPS [m] or None; total: how many. Order of k:
    tubes (or cylinders) 0-2, lemons 3-5 (rotary only), then the ceiling. A rotary
    robot's Rbar, L, tube and lemon are per leg, shape (3,), and ``radial`` (3, 3) holds
    each leg's base direction (a per-leg robot, kinematics/per_leg.py, has its own).
    """

    kind: str
    Rbar: Any
    axes: np.ndarray
    L: Any
    tube: Any
    lemon: Any
    top: float | None
    total: int  # how many constraints
    radial: np.ndarray = _U
    legs: tuple = ()  # per leg: (cos, sin, Rbar, L, tube, lemon) as floats (``_with_legs``)

    @property
    def centres(self) -> np.ndarray:
        """Knee-circle centres or rail points, shape (3, 3) [m]."""
        return np.asarray(self.Rbar, dtype=float).reshape(-1, 1) * self.radial

    def leg(self, leg: int) -> tuple[float, float, float, float, float, float]:
        """(cos, sin of its base direction, Rbar, L, tube, lemon) of one leg, as floats."""
        return self.legs[leg]

    def values(self, points: np.ndarray) -> np.ndarray:
        """c_k at points (N, 3): shape (N, total) [m]."""
        return self._evaluate(points, gradients=False)[0]

    def values_and_gradients(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """c_k (N, total) [m] and their gradients (N, total, 3)."""
        values, gradients = self._evaluate(points, gradients=True)
        assert gradients is not None
        return values, gradients

    def _evaluate(self, p: np.ndarray, gradients: bool) -> tuple[np.ndarray, np.ndarray | None]:
        n = len(p)
        columns: list[np.ndarray] = []
        grads: list[np.ndarray] = []
        with np.errstate(all="ignore"):
            if self.kind == "rotary":
                x = p @ self.radial.T - self.Rbar
                y = p @ self.axes.T
                z = np.broadcast_to(p[:, 2:3], x.shape)
                rho = np.hypot(x, z)
                near = np.hypot(rho - self.L, y)
                far = np.hypot(rho + self.L, y)
                columns += [near - self.tube, self.lemon - far]
                if gradients:
                    safe = rho > 0.0
                    rho1 = np.where(safe, rho, 1.0)
                    e = np.where(
                        safe[..., None],
                        (x[..., None] * self.radial + z[..., None] * _Z) / rho1[..., None],
                        self.radial,
                    )
                    ya = y[..., None] * self.axes
                    grads += [
                        ((rho - self.L)[..., None] * e + ya) / near[..., None],
                        -((rho + self.L)[..., None] * e + ya) / far[..., None],
                    ]
            else:
                w = p[:, None, :] - self.centres
                along = np.einsum("nkj,kj->nk", w, self.axes)
                perp = w - along[..., None] * self.axes
                dist = np.linalg.norm(perp, axis=-1)
                columns.append(dist - self.tube)
                if gradients:
                    grads.append(perp / dist[..., None])
            if self.top is not None:
                columns.append(p[:, 2:3] - self.top)
                if gradients:
                    grads.append(np.broadcast_to(_Z, (n, 1, 3)))
        values = np.concatenate(columns, axis=1)
        return values, (np.concatenate(grads, axis=1) if gradients else None)

    def faces(self, goal: tuple[float, float, float]) -> list[tuple[float, tuple]]:
        """Candidate local minima of |p - goal| on the constraint surfaces, in closed form.

        Returns (distance [m], point) pairs. A tube's only one is on the line from the
        nearest knee-circle point K to the goal at the tube's radius; a lemon's critical
        points are on the lines from the nearest or farthest point, at +-its radius.
        """
        gx, gy, gz = goal
        out: list[tuple[float, tuple]] = []
        if self.top is not None:
            out.append((abs(gz - self.top), (gx, gy, self.top)))
        for leg in range(3):
            cos, sin, Rbar, L, leg_tube, lemon = self.leg(leg)
            knees: list[tuple[tuple[float, float, float], tuple[float, ...]]] = []
            if self.kind == "linear":
                ax, ay, az = (float(v) for v in self.axes[leg])
                fx, fy = Rbar * cos, Rbar * sin
                along = (gx - fx) * ax + (gy - fy) * ay + gz * az
                knees.append(((fx + along * ax, fy + along * ay, along * az), (leg_tube,)))
            else:
                radial = cos * gx + sin * gy - Rbar
                rho = math.hypot(radial, gz)
                er, ez = (radial / rho, gz / rho) if rho > 0.0 else (1.0, 0.0)
                for side, tube in ((1.0, (leg_tube,)), (-1.0, ())):
                    reach = Rbar + side * L * er
                    knee = (reach * cos, reach * sin, side * L * ez)
                    knees.append((knee, (*tube, lemon, -lemon)))
            for (kx, ky, kz), radii in knees:
                vx, vy, vz = gx - kx, gy - ky, gz - kz
                length = math.sqrt(vx * vx + vy * vy + vz * vz)
                if not length > 0.0:
                    continue
                for radius in radii:
                    scale = radius / length
                    point = (kx + scale * vx, ky + scale * vy, kz + scale * vz)
                    out.append((abs(length - radius), point))
        return out

    def admits(self, x: float, y: float, z: float) -> bool:
        """Whether every (tightened) constraint holds at one point, up to _ADMIT."""
        return all(self.value(k, x, y, z) <= _ADMIT for k in range(self.total))

    def value(self, k: int, x: float, y: float, z: float) -> float:
        """c_k at one point, on Python floats."""
        if k == self.total - 1 and self.top is not None:
            return z - self.top
        cos, sin, Rbar, L, tube, lemon = self.leg(k % 3)
        if self.kind == "linear":
            ax, ay, az = self.axes[k % 3]
            wx, wy = x - Rbar * cos, y - Rbar * sin
            along = wx * ax + wy * ay + z * az
            return math.sqrt(max(wx * wx + wy * wy + z * z - along * along, 0.0)) - tube
        rho = math.hypot(cos * x + sin * y - Rbar, z)
        if k < 3:
            return math.hypot(rho - L, cos * y - sin * x) - tube
        return lemon - math.hypot(rho + L, cos * y - sin * x)

    def scalar(self, k: int, x: float, y: float, z: float) -> tuple[float, float, float, float]:
        """(c_k, grad c_k) at one point, on Python floats (the per-query Newton solves)."""
        if k == self.total - 1 and self.top is not None:
            return z - self.top, 0.0, 0.0, 1.0
        cos, sin, Rbar, L, tube, lemon = self.leg(k % 3)
        if self.kind == "linear":
            ax, ay, az = self.axes[k % 3]
            wx, wy = x - Rbar * cos, y - Rbar * sin
            along = wx * ax + wy * ay + z * az
            px, py, pz = wx - along * ax, wy - along * ay, z - along * az
            dist = math.sqrt(px * px + py * py + pz * pz)
            return dist - tube, px / dist, py / dist, pz / dist
        radial = cos * x + sin * y - Rbar
        axial = -sin * x + cos * y
        rho = math.hypot(radial, z)
        er, ez = (radial / rho, z / rho) if rho > 0.0 else (1.0, 0.0)
        if k < 3:
            shifted, value_sign = rho - L, 1.0
        else:
            shifted, value_sign = rho + L, -1.0
        dist = math.hypot(shifted, axial)
        value = dist - tube if k < 3 else lemon - dist
        gr = value_sign * shifted * er / dist
        ga = value_sign * axial / dist
        gz = value_sign * shifted * ez / dist
        return value, gr * cos - ga * sin, gr * sin + ga * cos, gz


def _with_legs(cons: Constraints) -> Constraints:
    """``cons`` with its per-leg floats precomputed (the per-query solves read them)."""

    def pick(value: Any, leg: int) -> float:
        return float(value[leg]) if np.ndim(value) else float(value)

    legs = tuple(
        (
            float(cons.radial[i][0]),
            float(cons.radial[i][1]),
            *(pick(getattr(cons, n), i) for n in ("Rbar", "L", "tube", "lemon")),
        )
        for i in range(3)
    )
    return cons._replace(legs=legs)


@functools.lru_cache(maxsize=64)
def constraints(robot: Any, margin: float, z_max: float | None) -> Constraints:
    """The tightened constraints of ``robot`` with ``margin`` [m] and ceiling ``z_max`` [m]
    (cached: shared, never to be changed)."""
    top = None if z_max is None else float(z_max) - EPS
    ceiling = top is not None
    if hasattr(robot, "L"):  # rotary: per leg (equal for a symmetric robot)
        legs = {n: np.broadcast_to(np.asarray(getattr(robot, n), float), (3,)) for n in "LlRr"}
        angles = getattr(robot, "angles_rad", None)
        radial, axes = _U, _A
        if angles is not None and tuple(angles) != LEG_ANGLES_RAD:
            c, s = np.cos(np.asarray(angles, float)), np.sin(np.asarray(angles, float))
            zero = np.zeros(3)
            radial, axes = np.column_stack([c, s, zero]), np.column_stack([-s, c, zero])
        return _with_legs(
            Constraints(
                "rotary",
                legs["R"] - legs["r"],
                axes,
                legs["L"].copy(),
                legs["l"] - margin - EPS,
                legs["l"] + margin + EPS,
                top,
                6 + ceiling,
                radial,
            )
        )
    Rbar = float(robot.R - robot.r)
    tube, lemon = float(robot.l - margin - EPS), float(robot.l + margin + EPS)
    rails = np.array([robot._rail(i) for i in range(3)])
    return _with_legs(Constraints("linear", Rbar, rails, 0.0, tube, lemon, top, 3 + ceiling))


class Boundary(NamedTuple):
    """What is computed once per (robot, margin, z_max).

    points (N + V, 3): N edge samples then the V admissible vertices [m]; squared: their
    |p|^2 [m^2]; barred: 0 where admissible, inf where not (edge samples within a grid
    cell of admissible are kept, so that links also bracket a minimum just before an
    edge's end); pairs (N, 2): the edge samples' two constraints;
    first, second (M,): the two samples of each link (second is the nearest sample ahead
    of first along their edge, within two grid cells); links (M,): their distance [m];
    tangent1, tangent2 (M, 3): unit grad c_a x grad c_b at each end; along1, along2 (M,):
    the ends' positions . their tangents [m]; longest: the longest link [m].
    """

    constraints: Constraints
    points: np.ndarray
    squared: np.ndarray
    barred: np.ndarray
    pairs: np.ndarray
    first: np.ndarray
    second: np.ndarray
    links: np.ndarray
    tangent1: np.ndarray
    tangent2: np.ndarray
    along1: np.ndarray
    along2: np.ndarray
    longest: float


@functools.lru_cache(maxsize=32)
def boundary(robot: Any, margin: float, z_max: float | None) -> Boundary:
    """Edges and vertices of the admissible set (cached: tens to hundreds of ms at first)."""
    cons = constraints(robot, margin, z_max)
    starts, pairs, cell = _edge_starts(cons, min(_CELL, 0.05 * float(np.min(robot.l))))
    edges, pairs = _onto_edges(cons, *_thin(starts, pairs, 0.25 * cell))
    edges, pairs = _thin(edges, pairs, 0.25 * cell)
    vertices = _vertices(cons, edges, pairs, cell)
    keep = _near_admissible(cons, edges, cell)
    edges, pairs = edges[keep], pairs[keep]
    for _ in range(2):  # halve the gaps: midpoints of every link, moved onto the edge
        first, second, _links_ = _links(edges, pairs, _tangents(cons, edges, pairs), 2.0 * cell)
        middle = 0.5 * (edges[first] + edges[second])
        middle, middle_pairs = _onto_edges(cons, middle, pairs[first], rounds=5)
        keep = _near_admissible(cons, middle, cell)
        edges = np.concatenate([edges, middle[keep]])
        pairs = np.concatenate([pairs, middle_pairs[keep]])
        cell *= 0.5
    tangents = _tangents(cons, edges, pairs)
    first, second, links = _links(edges, pairs, tangents, 2.0 * cell)
    along = np.einsum("nj,nj->n", edges, tangents)
    points = np.concatenate([edges, vertices])
    barred = np.where(_admissible(cons, points), 0.0, np.inf)
    return Boundary(
        constraints=cons,
        points=points,
        squared=np.einsum("nj,nj->n", points, points),
        barred=barred,
        pairs=pairs,
        first=first,
        second=second,
        links=links,
        tangent1=np.ascontiguousarray(tangents[first]),
        tangent2=np.ascontiguousarray(tangents[second]),
        along1=along[first],
        along2=along[second],
        longest=float(links.max()) if len(links) else cell,
    )


def _near_admissible(cons: Constraints, points: np.ndarray, slack: float) -> np.ndarray:
    if len(points) == 0:
        return np.zeros(0, dtype=bool)
    with np.errstate(invalid="ignore"):
        return np.isfinite(points).all(axis=1) & (cons.values(points) <= slack).all(axis=1)


def _thin(edges: np.ndarray, pairs: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """One sample per (pair, cube of side ``spacing``): the grid finds most points twice."""
    if len(edges) == 0:
        return edges, pairs
    key = np.column_stack([pairs, np.floor(edges / spacing)])
    _, first = np.unique(key, axis=0, return_index=True)
    return edges[first], pairs[first]


def _admissible(cons: Constraints, points: np.ndarray) -> np.ndarray:
    if len(points) == 0:
        return np.zeros(0, dtype=bool)
    with np.errstate(invalid="ignore"):
        return np.isfinite(points).all(axis=1) & (cons.values(points) <= _ADMIT).all(axis=1)


def _surfaces(cons: Constraints, cell: float) -> list[tuple[int, np.ndarray, bool, float]]:
    """Each leg surface on a grid: (constraint, points (N1, N2, 3), wraps in N2, cell [m])."""
    out = []
    if cons.kind == "rotary":
        for k in range(6):
            leg, sign = k % 3, (1.0 if k < 3 else -1.0)
            _, _, _, L, tube, lemon = cons.leg(leg)
            radius = tube if k < 3 else lemon
            if radius <= 0.0:
                continue
            cos_end = -sign * L / radius  # the surface ends where it meets the motor axis
            wraps = cos_end <= -1.0
            span = math.pi if wraps else math.acos(min(cos_end, 1.0))
            reach = max(sign * L + radius, 1e-6)
            (n1, n2), diagonal = _grid_shape(2.0 * math.pi * reach, 2.0 * span * radius, cell)
            psi = np.linspace(0.0, 2.0 * math.pi, n1, endpoint=False)
            phi = np.linspace(-span, span, n2, endpoint=not wraps)
            e = np.cos(psi)[:, None] * cons.radial[leg] + np.sin(psi)[:, None] * _Z
            ring = sign * L + radius * np.cos(phi)
            points = (
                cons.centres[leg]
                + ring[None, :, None] * e[:, None, :]
                + (radius * np.sin(phi))[None, :, None] * cons.axes[leg]
            )
            out.append((k, points, wraps, diagonal))
    elif cons.tube > 0.0:
        radius, half = cons.tube, _linear_extent(cons)
        for k in range(3):
            axis = cons.axes[k]
            v1 = np.cross(axis, _Z if abs(axis[2]) < 0.9 else _U[0])
            v1 /= np.linalg.norm(v1)
            v2 = np.cross(axis, v1)
            apex = -float(np.dot(cons.centres[k], axis))  # where the rails meet
            (n1, n2), diagonal = _grid_shape(2.0 * half, 2.0 * math.pi * radius, cell)
            t = np.linspace(apex - half, apex + half, n1)
            phi = np.linspace(0.0, 2.0 * math.pi, n2, endpoint=False)
            ring = radius * (np.cos(phi)[:, None] * v1 + np.sin(phi)[:, None] * v2)
            points = cons.centres[k] + t[:, None, None] * axis + ring[None, :, :]
            out.append((k, points, True, diagonal))
    return out


def _linear_extent(cons: Constraints) -> float:
    """Half-length [m] of rail about the rails' common point holding every admissible point.

    Inside two cylinders of radius r whose axes meet at angle beta, a point is within
    r / sin(min(beta, pi - beta) / 2) of the common point in their plane and r off it.
    """
    beta = math.acos(min(abs(float(np.dot(cons.axes[0], cons.axes[1]))), 1.0))
    inplane = cons.tube / max(math.sin(beta / 2.0), 1e-3)
    return math.hypot(inplane, cons.tube) + cons.tube


def _grid_shape(length1: float, length2: float, cell: float) -> tuple[tuple[int, int], float]:
    """Grid points along two lengths [m] for cells of about ``cell``, and the cell diagonal."""
    cell = max(cell, math.sqrt(max(length1 * length2, 1e-12) / _GRID_POINTS))
    n1, n2 = max(8, math.ceil(length1 / cell)), max(8, math.ceil(length2 / cell) + 1)
    return (n1, n2), math.hypot(length1 / n1, length2 / (n2 - 1))


def _edge_starts(cons: Constraints, cell: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Where another constraint changes sign between grid neighbours on a surface.

    Returns approximate edge points (N, 3), their constraint pairs (N, 2) (surface first)
    and the largest grid-cell diagonal [m].
    """
    found, pairs = [], []
    widest = 0.0
    legs = cons.total - (cons.top is not None)
    for k, grid, wraps, diagonal in _surfaces(cons, cell):
        widest = max(widest, diagonal)
        n1, n2 = grid.shape[:2]
        values = cons.values(grid.reshape(-1, 3)).reshape(n1, n2, -1)
        for other in range(cons.total):
            if other == k or (other < legs and other < k):
                continue  # each pair of leg surfaces once, from the lower-numbered one
            s = values[..., other]
            for axis, periodic in ((0, cons.kind == "rotary"), (1, wraps)):
                a_vals, b_vals = s, np.roll(s, -1, axis=axis)
                a_pts, b_pts = grid, np.roll(grid, -1, axis=axis)
                if not periodic:
                    cut = (slice(0, -1), slice(None)) if axis == 0 else (slice(None), slice(0, -1))
                    a_vals, b_vals, a_pts, b_pts = a_vals[cut], b_vals[cut], a_pts[cut], b_pts[cut]
                with np.errstate(invalid="ignore"):
                    cross = ((a_vals <= 0.0) != (b_vals <= 0.0)) & np.isfinite(a_vals + b_vals)
                t = (a_vals[cross] / (a_vals[cross] - b_vals[cross]))[:, None]
                found.append(a_pts[cross] + t * (b_pts[cross] - a_pts[cross]))
                pairs.append(np.tile([k, other], (len(t), 1)))
    # a rotary tube meets its own lemon on two circles about the motor axis
    for leg in range(3) if cons.kind == "rotary" else ():
        _, _, _, L, tube, lemon = cons.leg(leg)
        rho = (lemon**2 - tube**2) / (4.0 * L)
        along_sq = tube**2 - (rho - L) ** 2
        if along_sq > 0.0:
            count = max(8, math.ceil(2.0 * math.pi * rho / cell))
            psi = np.linspace(0.0, 2.0 * math.pi, count, endpoint=False)
            widest = max(widest, 2.0 * math.pi * rho / count)
            e = np.cos(psi)[:, None] * cons.radial[leg] + np.sin(psi)[:, None] * _Z
            for sign in (1.0, -1.0):
                found.append(
                    cons.centres[leg] + rho * e + sign * math.sqrt(along_sq) * cons.axes[leg]
                )
                pairs.append(np.tile([leg, leg + 3], (count, 1)))
    if not found:
        return np.zeros((0, 3)), np.zeros((0, 2), dtype=int), widest
    return np.concatenate(found), np.concatenate(pairs).astype(int), widest


def _onto_edges(
    cons: Constraints, points: np.ndarray, pairs: np.ndarray, rounds: int = 10
) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Newton (least-norm steps) onto c_a = c_b = 0; drops what does not converge."""
    p, pairs = points.copy(), pairs.copy()
    todo = np.arange(len(p))
    for _ in range(rounds):
        if len(todo) == 0:
            break
        values, grads = cons.values_and_gradients(p[todo])
        c = np.take_along_axis(values, pairs[todo], axis=1)  # (N, 2)
        J = np.take_along_axis(grads, pairs[todo][..., None], axis=1)  # (N, 2, 3)
        gram = J @ J.transpose(0, 2, 1) + 1e-15 * np.eye(2)
        with np.errstate(all="ignore"):
            step = np.linalg.solve(gram, c[..., None])
        p[todo] -= (J.transpose(0, 2, 1) @ step)[..., 0]
        with np.errstate(invalid="ignore"):
            todo = todo[~(np.abs(c) < 1e-14).all(axis=1)]
    if len(p) == 0:
        return p, pairs
    c = np.take_along_axis(cons.values(p), pairs, axis=1)
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(p).all(axis=1) & (np.abs(c) < 1e-12).all(axis=1)
    return p[ok], pairs[ok]


def _tangents(cons: Constraints, edges: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    if len(edges) == 0:
        return np.zeros((0, 3))
    grads = cons.values_and_gradients(edges)[1]
    rows = np.arange(len(edges))
    tangent = np.cross(grads[rows, pairs[:, 0]], grads[rows, pairs[:, 1]])
    with np.errstate(all="ignore"):
        return tangent / np.linalg.norm(tangent, axis=1, keepdims=True)


def _links(
    edges: np.ndarray, pairs: np.ndarray, tangents: np.ndarray, longest: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each sample's nearest sample ahead (along its tangent) on the same edge.

    Returns (first, second, length [m]) of every link no longer than ``longest``.
    """
    n = len(edges)
    if n < 2:
        return np.zeros(0, dtype=int), np.zeros(0, dtype=int), np.zeros(0)
    from scipy.spatial import cKDTree  # here, not at import: scipy costs the CLI ~0.5 s

    distance, index = cKDTree(edges).query(edges, k=min(10, n))
    ahead = np.einsum("nkj,nj->nk", edges[index] - edges[:, None, :], tangents) > 0.0
    same = (pairs[index] == pairs[:, None, :]).all(axis=-1)
    valid = ahead & same & (distance > 0.0) & (distance <= longest)
    rows = np.arange(n)
    pick = np.argmax(valid, axis=1)
    has = valid[rows, pick]
    return rows[has], index[rows, pick][has], distance[rows, pick][has]


def _vertices(cons: Constraints, edges: np.ndarray, pairs: np.ndarray, cell: float) -> np.ndarray:
    """Newton on three constraints from edge samples near a third surface (one per cell)."""
    if len(edges) == 0:
        return np.zeros((0, 3))
    values = cons.values(edges)
    starts, triples = [], []
    for k in range(cons.total):
        with np.errstate(invalid="ignore"):
            near = (np.abs(values[:, k]) < cell) & (pairs != k).all(axis=1)
        key = np.column_stack([pairs[near], np.floor(edges[near] / cell)])
        _, first = np.unique(key, axis=0, return_index=True)
        starts.append(edges[near][first])
        triples.append(np.column_stack([pairs[near][first], np.full(len(first), k)]))
    p, triple = np.concatenate(starts), np.concatenate(triples).astype(int)
    for _ in range(12):
        values_p, grads = cons.values_and_gradients(p)
        c = np.take_along_axis(values_p, triple, axis=1)
        J = np.take_along_axis(grads, triple[..., None], axis=1)
        with np.errstate(all="ignore"):
            step = np.linalg.solve(J + 1e-13 * np.eye(3), c[..., None])[..., 0]
        length = np.linalg.norm(step, axis=1, keepdims=True)
        with np.errstate(all="ignore"):
            p = p - step * np.minimum(1.0, cell / length)
    c = np.take_along_axis(cons.values(p), triple, axis=1)
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(p).all(axis=1) & (np.abs(c) < 1e-11).all(axis=1)
    found = p[ok][_admissible(cons, p[ok])]
    _, first = np.unique(np.round(found, 9), axis=0, return_index=True)  # one of each
    return found[first]


def nearest(robot: Any, goal: np.ndarray, margin: float, z_max: float | None) -> np.ndarray | None:
    """Nearest admissible point to ``goal`` (3,) [m], or None where nothing is admissible.

    See the module docstring for the method. The caller checks the answer with the IK.
    """
    ceiling = None if z_max is None else float(z_max)
    if not hasattr(robot, "L") and abs(robot._rail(0)[2]) >= 1.0 - 1e-15:
        return _nearest_parallel_rails(constraints(robot, margin, ceiling), goal)
    found = boundary(robot, float(margin), ceiling)
    cons = found.constraints
    g = (float(goal[0]), float(goal[1]), float(goal[2]))
    faces = sorted(cons.faces(g), key=lambda item: item[0])
    # Every c_k is 1-Lipschitz, so no admissible point is nearer than the largest violation:
    # a face's nearest point that is admissible and that near is the answer.
    lower = max(0.0, *(cons.value(k, *g) for k in range(cons.total)))
    if faces and faces[0][0] <= lower + 1e-12 and cons.admits(*faces[0][1]):
        return np.array(faces[0][1])
    best: tuple | None = None
    best_distance = math.inf
    squared = found.squared - 2.0 * (found.points @ goal) + float(goal @ goal)
    if len(squared):
        index = int(np.argmin(squared + found.barred))
        if found.barred[index] == 0.0:
            best, best_distance = tuple(found.points[index]), math.dist(found.points[index], g)
    for distance, point in faces:
        if distance >= best_distance:
            break
        if cons.admits(*point):
            best, best_distance = point, distance
            break
    if best is None:
        return None
    for start, pair in _brackets(found, goal, squared, best_distance):
        solved = _solve_edge(cons, g, start, pair, found.longest)
        if solved is not None:
            distance = math.dist(solved, g)
            if distance < best_distance:
                best, best_distance = solved, distance
    return np.array(best)


def _brackets(
    found: Boundary, goal: np.ndarray, squared: np.ndarray, bar: float
) -> list[tuple[np.ndarray, tuple[int, int]]]:
    """Links along which the distance falls then rises and may get below ``bar`` [m].

    Along a link of length s from sample i to j the distance f is at least
    (f_i + f_j - s) / 2 (f is 1-Lipschitz; 1.1 s allows for the edge's bend): links whose
    bound is below ``bar``, lowest bound first (at most _MOST_SOLVES), as (the nearer
    end, the edge's pair of constraints). ``squared``: |points - goal|^2, shape (N + V,).
    """
    if len(found.first) == 0:
        return []
    # d/ds |p - goal|^2 / 2 along the edge at both ends of every link
    falls = found.along1 - found.tangent1 @ goal <= 0.0
    rises = found.along2 - found.tangent2 @ goal >= 0.0
    turn = np.flatnonzero(falls & rises)
    i, j = found.first[turn], found.second[turn]
    fi = np.sqrt(np.maximum(squared[i], 0.0))
    fj = np.sqrt(np.maximum(squared[j], 0.0))
    bound = 0.5 * (fi + fj - 1.1 * found.links[turn])
    below = np.flatnonzero(bound < bar)
    out = []
    for o in below[np.argsort(bound[below])][:_MOST_SOLVES].tolist():
        start = found.points[i[o] if fi[o] <= fj[o] else j[o]]
        out.append((start, (int(found.pairs[i[o], 0]), int(found.pairs[i[o], 1]))))
    return out


def _solve_edge(
    cons: Constraints,
    goal: tuple[float, float, float],
    start: np.ndarray,
    pair: tuple,
    longest: float,
) -> tuple[float, float, float] | None:
    """Newton on (c_a, c_b, (goal - p).(grad c_a x grad c_b)) = 0 from ``start``, on floats.

    The Jacobian's first two rows are the gradients, the third is by forward differences.
    Returns the point if it converged onto the edge and every constraint admits it.
    """
    a, b = int(pair[0]), int(pair[1])
    gx, gy, gz = goal
    x, y, z = (float(v) for v in start)

    def residual(x: float, y: float, z: float) -> tuple[float, float, float, tuple, tuple]:
        ca, ax, ay, az = cons.scalar(a, x, y, z)
        cb, bx, by, bz = cons.scalar(b, x, y, z)
        tx, ty, tz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
        return ca, cb, (gx - x) * tx + (gy - y) * ty + (gz - z) * tz, (ax, ay, az), (bx, by, bz)

    ca, cb, h, ra, rb = residual(x, y, z)
    rc = tuple((residual(*p)[2] - h) / _FD for p in _probes(x, y, z))
    for _ in range(12):
        step = _solve3(ra, rb, rc, (ca, cb, h))
        if step is None:
            return None
        length = math.sqrt(step[0] ** 2 + step[1] ** 2 + step[2] ** 2)
        scale = min(1.0, longest / length) if length > 0.0 else 1.0
        dx, dy, dz = -scale * step[0], -scale * step[1], -scale * step[2]
        x, y, z = x + dx, y + dy, z + dz
        ca, cb, moved, ra, rb = residual(x, y, z)
        # Broyden's update of the third row (forward differences at the start only)
        norm2 = dx * dx + dy * dy + dz * dz
        if norm2 > 0.0:
            miss = (moved - h - (rc[0] * dx + rc[1] * dy + rc[2] * dz)) / norm2
            rc = (rc[0] + miss * dx, rc[1] + miss * dy, rc[2] + miss * dz)
        h = moved
        if length < 1e-11:
            break
    if not (abs(ca) < 1e-12 and abs(cb) < 1e-12):
        return None
    if not cons.admits(x, y, z):
        return None
    return x, y, z


def _probes(x: float, y: float, z: float) -> tuple[tuple[float, float, float], ...]:
    return (x + _FD, y, z), (x, y + _FD, z), (x, y, z + _FD)


def _solve3(r0: tuple, r1: tuple, r2: tuple, rhs: tuple) -> tuple[float, float, float] | None:
    """Cramer's rule for the 3x3 system with rows r0, r1, r2; None if singular."""
    det = (
        r0[0] * (r1[1] * r2[2] - r1[2] * r2[1])
        - r0[1] * (r1[0] * r2[2] - r1[2] * r2[0])
        + r0[2] * (r1[0] * r2[1] - r1[1] * r2[0])
    )
    if not abs(det) > 1e-300 or not math.isfinite(det):
        return None
    out = []
    for col in range(3):
        m = [list(r0), list(r1), list(r2)]
        for row in range(3):
            m[row][col] = rhs[row]
        out.append(
            (
                m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
                - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
                + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
            )
            / det
        )
    return out[0], out[1], out[2]


def _nearest_parallel_rails(cons: Constraints, goal: np.ndarray) -> np.ndarray | None:
    """Vertical rails: the set is a prism (three discs in x, y) below the ceiling; exact.

    The nearest point of an intersection of discs is the goal, the nearest point of one
    disc, or a corner where two discs' circles cross: the nearest admissible of these.
    """
    radius = cons.tube
    if radius <= 0.0:
        return None
    gx, gy = float(goal[0]), float(goal[1])
    centres = [(cons.Rbar * LEG_COS[i], cons.Rbar * LEG_SIN[i]) for i in range(3)]
    points = [(gx, gy)]
    for cx, cy in centres:
        length = math.hypot(gx - cx, gy - cy)
        if length > 0.0:
            points.append((cx + radius * (gx - cx) / length, cy + radius * (gy - cy) / length))
    for i, j in ((0, 1), (1, 2), (0, 2)):
        (ax, ay), (bx, by) = centres[i], centres[j]
        length = math.hypot(bx - ax, by - ay)
        half = math.sqrt(max(radius * radius - 0.25 * length * length, 0.0))
        if length > 0.0:
            mx, my = 0.5 * (ax + bx), 0.5 * (ay + by)
            nx, ny = -(by - ay) / length, (bx - ax) / length
            points += [(mx + half * nx, my + half * ny), (mx - half * nx, my - half * ny)]
    inside = [
        p
        for p in points
        if all(math.hypot(p[0] - cx, p[1] - cy) <= radius + _ADMIT for cx, cy in centres)
    ]
    if not inside:
        return None
    x, y = min(inside, key=lambda p: math.hypot(p[0] - gx, p[1] - gy))
    z = float(goal[2]) if cons.top is None else min(float(goal[2]), cons.top)
    return np.array([x, y, z])
