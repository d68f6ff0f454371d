"""Geometric synthesis (kinematics/synthesis.py) and certified containment."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from kinematics import THESIS_DELTA, RotaryDelta
from kinematics.containment import certify_box
from kinematics.synthesis import (
    THESIS_DESIGN,
    Bounds,
    DesiredVolume,
    Problem,
    score,
    synthesize,
    torus_h,
    violations,
)
from kinematics.torus import torus_distance, torus_inside


def test_torus_distance_and_inside_are_the_robots():
    points = np.random.default_rng(1).uniform(-0.4, 0.4, (2000, 3))
    d = THESIS_DESIGN
    distance = torus_distance(d.L, d.l, d.Rbar, points)
    np.testing.assert_allclose(distance.max(-1), THESIS_DELTA.signed_distance(points), atol=1e-15)
    for clearance in (0.0, 1e-3, 0.02):
        inside = torus_inside(d.L, d.l, d.Rbar, points, clearance)
        np.testing.assert_array_equal(inside, distance <= -clearance)


def test_torus_h_is_the_robots_h():
    points = np.random.default_rng(0).uniform(-0.4, 0.4, (50, 3))
    d = THESIS_DESIGN
    np.testing.assert_allclose(
        torus_h(d.L, d.l, d.Rbar, points), THESIS_DELTA.h(points), atol=1e-15
    )


@pytest.mark.slow
def test_point_problem_has_its_known_answer():
    """One point (0, 0, -H): h_i = 0 exactly when l = sqrt(Rbar^2 + H^2) +- L.

    On the axis every leg sees E = 2 L Rbar, F = -2 L H, G = H^2 + Rbar^2 + L^2 - l^2,
    and G^2 = E^2 + F^2 gives l^2 = rho^2 + L^2 -+ 2 L rho with rho = |(Rbar, H)|.
    """
    problem = Problem(DesiredVolume(size_m=(0.0, 0.0, 0.0), extra_points=()), clearance_m=0.0)
    result = synthesize(problem, popsize=10, maxiter=80, seed=1, tol=1e-6)
    d = result.design
    rho = math.hypot(d.Rbar, d.H)
    assert result.power_of_point < 1e-5  # of ~1e-2 for a typical design
    assert min(abs(d.l - (rho + d.L)), abs(d.l - (rho - d.L))) < 2e-3
    assert result.contains


def test_thesis_design_misses_the_box_bottom_by_six_centimetres():
    """Regression: Table 4.3 with H the depth of the 22 cm box's top face."""
    problem = Problem()
    found = violations(problem, THESIS_DESIGN)
    assert all(v.point[2] == pytest.approx(-0.4103) for v in found)  # only bottom vertices
    assert len({v.point for v in found}) == 4
    assert max(v.outside_m for v in found) == pytest.approx(0.0609, abs=5e-4)
    assert score(problem, np.array(THESIS_DESIGN)).violations >= 12
    robot = THESIS_DESIGN.robot()
    lower, upper = problem.volume.box(THESIS_DESIGN.H)
    verdict = certify_box(robot, lower, upper)
    assert verdict.contains is False
    assert robot.signed_distance(verdict.witness) > 0
    assert robot.reachable([0.0, 0.0, -0.075])  # the landing point is inside (by 1 mm)


def test_thesis_design_holds_a_20cm_cube_centred_at_depth_h():
    """The reading under which Table 4.3 works: cube centre at -H, no 1 cm margin."""
    c = np.array([0.0, 0.0, -THESIS_DESIGN.H])
    assert certify_box(THESIS_DESIGN.robot(), c - 0.1, c + 0.1, tol=0.0).contains is True


@pytest.mark.slow
def test_quick_search_beats_the_thesis_and_is_certified():
    problem = Problem()
    result = synthesize(problem, popsize=12, maxiter=60, seed=3)
    thesis = score(problem, np.array(THESIS_DESIGN))
    assert result.contains and result.containment.contains is True  # with no tolerance
    robot = result.design.robot()
    lower, upper = problem.volume.box(result.design.H)
    inside = np.random.default_rng(0).uniform(lower, upper, (20000, 3))
    assert (
        robot.reachable(inside).all()
        and robot.reachable(problem.thesis_points(result.design.H)).all()
    )
    assert result.power_of_point <= thesis.power_of_point
    assert result.objective == result.power_of_point  # no penalty left
    b = Bounds()
    for value, (low, high) in zip(result.design, b.as_list(), strict=True):
        assert low <= value <= high
    assert result.design.l > result.design.L


def test_score_is_vectorized_like_a_loop():
    rng = np.random.default_rng(5)
    x = np.array([rng.uniform(a, b, 7) for a, b in Bounds().as_list()])
    together = score(Problem(), x)
    for k in range(7):
        alone = score(Problem(), x[:, k])
        assert together.objective[k] == pytest.approx(float(alone.objective), rel=1e-12)


@given(st.floats(0.08, 0.2), st.floats(1.3, 2.5), st.floats(0.0, 0.08), st.integers(0, 2**32 - 1))
def test_certification_is_sound(L, ratio, Rbar, seed):
    """contains=True: no sampled point is outside by more than tol; False: a true witness."""
    robot = RotaryDelta(L=L, l=L * ratio, R=Rbar + 0.02, r=0.02)
    rng = np.random.default_rng(seed)
    centre = np.array([0.0, 0.0, -rng.uniform(0.1, 0.4)]) + rng.uniform(-0.05, 0.05, 3)
    half = rng.uniform(0.01, 0.12, 3)
    lower, upper = centre - half, centre + half
    verdict = certify_box(robot, lower, upper, tol=1e-4)
    if verdict.contains:
        samples = rng.uniform(lower, upper, (2000, 3))
        assert (robot.signed_distance(samples) <= 1e-4).all()
    elif verdict.contains is False:
        assert robot.signed_distance(verdict.witness) > 0
        assert (verdict.witness >= lower).all() and (verdict.witness <= upper).all()
