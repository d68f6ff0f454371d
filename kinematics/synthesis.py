"""Geometric synthesis of a rotary Delta for a desired volume (thesis ch. 4.1, Laribi et al.).

Find I_H = (L, l, Rbar, H) whose workspace holds a box (top face at depth H below the
base) plus extra points, with the smallest power-of-point objective (eq. 4.5-4.10):

    F = F1 + F2,  F1 = C * #{(k, i): h_i(P_k) > 0},  F2 = sum_k sum_i |h_i(P_k)|

over the box's vertices and the extra points, h_i the per-leg torus function (eq. 4.2,
read h = G^2 - E^2 - F^2; [m^4]). The workspace is not convex, so vertices are not
enough: our penalty also counts points sampled on the box's faces and inside it, each
asked to be ``clearance_m`` inside so that a proof can close; the winner is certified by
:func:`containment.certify_box`, and a witness found there joins the samples for another
search. F2 is always the thesis's (vertices and extra points), so objectives compare
with Table 4.3.

Pure: the caller passes a ``callback`` for progress (the CLI's progress bar).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from ._arrays import triple_floats
from .containment import Containment, certify_box, unit_box_samples
from .errors import InvalidGeometryError
from .rotary import RotaryDelta
from .torus import torus_h, torus_inside

_UNIT_CORNERS = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)

PENALTY = 1.0
"""C of eq. 4.9 [m^4]: F2 of any design in the bounds is ~1e-3, so one violation loses."""

THESIS_PLATFORM_RADIUS_M = 0.038
"""r of eq. 4.11: R = Rbar + r."""


@dataclass(frozen=True)
class DesiredVolume:
    """A box centred on the z axis with its top face at depth H, plus extra points.

    Attributes:
        size_m: box edges along x, y, z [m]; the thesis's 20 cm cube plus 1 cm each side.
        extra_points: points that must be reachable too [m], e.g. the compact landing
            pose (0, 0, -0.085) moved 1 cm nearer the base.
    """

    size_m: tuple[float, float, float] = (0.22, 0.22, 0.22)
    extra_points: tuple[tuple[float, float, float], ...] = ((0.0, 0.0, -0.075),)

    def __post_init__(self) -> None:
        if len(self.size_m) != 3 or not all(np.isfinite(self.size_m)) or min(self.size_m) < 0:
            raise InvalidGeometryError(f"size_m = {self.size_m!r}: three finite sizes >= 0 [m]")

    def box(self, H: Any) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper corners [m] for top depth(s) H, each shape (*H, 3)."""
        H = np.asarray(H, float)[..., None]
        size = np.asarray(self.size_m)
        upper = np.concatenate([np.broadcast_to(size[:2] / 2, H.shape[:-1] + (2,)), -H], -1)
        return upper - size, upper

    def vertices(self, H: Any) -> np.ndarray:
        """The box's eight vertices, shape (*H, 8, 3) [m]."""
        return self._scaled(
            H, np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        )

    def _scaled(self, H: Any, unit: np.ndarray) -> np.ndarray:
        lower, upper = self.box(H)
        return lower[..., None, :] + unit * (upper - lower)[..., None, :]


@dataclass(frozen=True)
class Bounds:
    """Search intervals [m] (thesis Table 4.2)."""

    L: tuple[float, float] = (0.05, 0.2)
    l: tuple[float, float] = (0.05, 0.3)
    Rbar: tuple[float, float] = (0.03, 0.05)
    H: tuple[float, float] = (0.19, 0.29)

    def as_list(self) -> list[tuple[float, float]]:
        return [self.L, self.l, self.Rbar, self.H]


class Design(NamedTuple):
    """Independent geometry (thesis I_H) [m]."""

    L: float
    l: float
    Rbar: float
    H: float

    def robot(self, r: float = THESIS_PLATFORM_RADIUS_M) -> RotaryDelta:
        """The Delta with platform radius ``r`` [m] and R = Rbar + r."""
        return RotaryDelta(L=self.L, l=self.l, R=self.Rbar + r, r=r)


THESIS_DESIGN = Design(L=0.1558, l=0.2430, Rbar=0.0464, H=0.1903)
"""Table 4.3, with the printed Rbar = 0.4637 read as 0.0464 (R - r = 0.0844 - 0.038)."""


@dataclass(frozen=True)
class Problem:
    """A synthesis problem: the volume, the search bounds and the penalty samples.

    ``extra_unit`` are further sample points in the box's unit coordinates, [0, 1]^3
    (witnesses of earlier failed certifications). ``clearance_m``: every sampled point
    must be this far inside [m], so that the certification can prove containment with
    no tolerance (a box touching the boundary can never be proved inside).
    """

    volume: DesiredVolume = DesiredVolume()
    bounds: Bounds = Bounds()
    per_edge: int = 7
    extra_unit: tuple[tuple[float, float, float], ...] = field(default=())
    clearance_m: float = 1e-4

    def unit_samples(self) -> np.ndarray:
        samples = unit_box_samples(self.per_edge)
        if self.extra_unit:
            samples = np.concatenate([samples, np.asarray(self.extra_unit, float)])
        return samples

    def thesis_points(self, H: Any) -> np.ndarray:
        """Vertices and extra points P_k of eq. 4.5, shape (*H, 8 + E, 3) [m]."""
        vertices = self.volume.vertices(H)
        extra = np.asarray(self.volume.extra_points, float).reshape(-1, 3)
        extra = np.broadcast_to(extra, vertices.shape[:-2] + extra.shape)
        return np.concatenate([vertices, extra], axis=-2)


class Score(NamedTuple):
    """Objective parts for designs, each shape (*S)."""

    objective: np.ndarray  # F1 + F2 [m^4]
    power_of_point: np.ndarray  # F2 (eq. 4.10) over vertices and extra points [m^4]
    violations: np.ndarray  # count of (point, leg) with h > 0 among all samples, or l <= L


def score(problem: Problem, x: Any, samples: np.ndarray | None = None) -> Score:
    """Eq. 4.7-4.10 for designs ``x`` = (L, l, Rbar, H) [m], shape (4, *S) or (4,)."""
    L, l, Rbar, H = np.asarray(x, float)
    points = problem.thesis_points(H)
    h = torus_h(L, l, Rbar, points)
    pop = np.abs(h).sum(axis=(-2, -1))
    unit = problem.unit_samples() if samples is None else samples
    lower, upper = problem.volume.box(H)
    sampled = lower[..., None, :] + unit * (upper - lower)[..., None, :]
    # h > 0 <=> distance > 0; the distance also gives the clearance in metres
    every = np.concatenate([points, np.broadcast_to(sampled, np.shape(sampled))], axis=-2)
    outside = ~torus_inside(L, l, Rbar, every, problem.clearance_m)
    violations = outside.sum(axis=(-2, -1)) + (l <= L)
    return Score(pop + PENALTY * violations, pop, violations)


class SynthesisResult(NamedTuple):
    """Outcome of :func:`synthesize`.

    design: best (L, l, Rbar, H) [m]; objective, power_of_point: F and F2 [m^4];
    containment: the certification of the box (and the extra points) for ``design``;
    evaluations: designs evaluated; rounds: searches run (witnesses added between).
    """

    design: Design
    objective: float
    power_of_point: float
    containment: Containment
    extra_points_ok: bool
    evaluations: int
    rounds: int

    @property
    def contains(self) -> bool:
        return bool(self.containment.contains) and self.extra_points_ok


def check(problem: Problem, design: Design, tol: float = 0.0) -> tuple[Containment, bool]:
    """Certify the box and test the extra points for one design (see containment.py)."""
    robot = design.robot()
    lower, upper = problem.volume.box(design.H)
    extra = np.asarray(problem.volume.extra_points, float).reshape(-1, 3)
    extra_ok = bool((robot.signed_distance(extra) <= tol).all()) if len(extra) else True
    return certify_box(robot, lower, upper, tol=tol), extra_ok


def _search(
    problem: Problem, popsize: int, maxiter: int, seed: int, on_generation: Callable[[Any], None]
) -> tuple[Design, int]:
    """One differential-evolution run; returns the best design and designs evaluated."""
    samples = problem.unit_samples()
    evaluations = 0

    def objective(x: np.ndarray) -> np.ndarray:
        nonlocal evaluations
        evaluations += x.shape[1] if x.ndim == 2 else 1
        return score(problem, x, samples).objective

    # polish=False: F is a step function of the penalty, a gradient polish can't help.
    # tol=1e-4 (population spread / mean): stopping there costs 1e-5 of the objective.
    from scipy.optimize import differential_evolution  # here: scipy is slow to import

    found = differential_evolution(
        objective,
        problem.bounds.as_list(),
        popsize=popsize,
        maxiter=maxiter,
        rng=seed,
        vectorized=True,
        updating="deferred",
        polish=False,
        tol=1e-4,
        callback=on_generation,
    )
    return Design(*(float(v) for v in found.x)), evaluations


def synthesize(
    problem: Problem = Problem(),
    *,
    popsize: int = 40,
    maxiter: int = 300,
    seed: int = 0,
    rounds: int = 3,
    tol: float = 0.0,
    callback: Callable[[int, float], None] | None = None,
) -> SynthesisResult:
    """Differential evolution on eq. 4.7, then certification; repeat with any witness.

    Args:
        problem: volume, bounds and samples.
        popsize, maxiter: scipy's differential_evolution settings (population is
            popsize * 4 designs, evaluated in one vectorized call per generation).
        seed: for repeatable runs.
        rounds: searches at most; each failed certification adds its witness point.
        tol: certification tolerance [m] (see :func:`containment.certify_box`); 0: every
            point of the box reachable, which ``problem.clearance_m`` makes provable.
        callback: called as callback(generation, best objective) after each generation.
    """
    evaluations, generation = 0, 0

    def progress(intermediate_result: Any) -> None:
        nonlocal generation
        generation += 1
        if callback is not None:
            callback(generation, float(intermediate_result.fun))

    for round_ in range(1, rounds + 1):
        design, spent = _search(problem, popsize, maxiter, seed, progress)
        evaluations += spent
        containment, extra_ok = check(problem, design, tol)
        if containment.contains is not False or round_ == rounds:
            break
        assert containment.witness is not None  # certify_box names one whenever contains is False
        problem = _with_witness(problem, design, containment.witness)
    final = score(problem, np.array(design))
    return SynthesisResult(
        design,
        float(final.objective),
        float(final.power_of_point),
        containment,
        extra_ok,
        evaluations,
        round_,
    )


def _with_witness(problem: Problem, design: Design, witness: np.ndarray) -> Problem:
    """The problem with ``witness`` [m] added to the penalty samples (in unit coordinates)."""
    lower, upper = problem.volume.box(design.H)
    unit = (witness - lower) / np.where(upper > lower, upper - lower, 1.0)
    extra = (*problem.extra_unit, triple_floats(unit, "witness"))
    return Problem(problem.volume, problem.bounds, problem.per_edge, extra, problem.clearance_m)


class Violation(NamedTuple):
    """One thesis point P_k that leg ``leg`` (0-2) cannot reach: h [m^4] and by how far [m]."""

    point: tuple[float, float, float]
    leg: int
    h: float
    outside_m: float


def violations(problem: Problem, design: Design) -> list[Violation]:
    """The vertices and extra points of eq. 4.5 out of some leg's reach, worst first."""
    robot = design.robot()
    points = problem.thesis_points(design.H)
    h = torus_h(design.L, design.l, design.Rbar, points)
    found = []
    for k, leg in zip(*np.nonzero(h > 0), strict=True):
        x, y, z = points[k]
        distance = float(robot._leg_signed_distance(int(leg), x, y, z))
        found.append(
            Violation((float(x), float(y), float(z)), int(leg), float(h[k, leg]), distance)
        )
    return sorted(found, key=lambda v: -v.outside_m)
