"""Workspace: torus functions, reachability, distance to the boundary, projection."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from kinematics import (
    THESIS_DELTA,
    LinearDelta,
    NonFiniteError,
    ShapeError,
    UnreachableError,
)
from tests.support.strategies import linear_deltas, rotary_deltas

ALPHA = np.radians([0.0, 120.0, 240.0])


def _box(robot, n, seed):
    """Random points in a box that holds the whole workspace and plenty around it."""
    size = robot.l + getattr(robot, "L", 0.0) + robot.R
    rng = np.random.default_rng(seed)
    return rng.uniform([-size, -size, -1.5 * size], [size, size, 0.5 * size], (n, 3))


@pytest.mark.slow
@given(st.one_of(rotary_deltas(), linear_deltas()), st.integers(0, 2**32 - 1))
def test_h_sign_agrees_with_ik(robot, seed):
    points = _box(robot, 2000, seed)
    assert np.array_equal(robot.reachable(points), robot.ik(points).ok)
    inside = (robot.h(points) <= 0).all(axis=-1)
    assert np.array_equal(inside, robot.ik(points).ok)


@given(rotary_deltas(), st.integers(0, 2**32 - 1))
def test_h_is_the_torus_of_eq_4_4(robot, seed):
    """h_i in leg i's local frame: [(x-Rb)^2 + y^2 + z^2 + L^2 - l^2]^2 - 4 L^2 [(x-Rb)^2 + z^2]."""
    points = _box(robot, 200, seed)
    L, l, Rb = robot.L, robot.l, robot.Rbar
    for i, alpha in enumerate(ALPHA):
        x = np.cos(alpha) * points[:, 0] + np.sin(alpha) * points[:, 1]
        y = -np.sin(alpha) * points[:, 0] + np.cos(alpha) * points[:, 1]
        z = points[:, 2]
        torus = ((x - Rb) ** 2 + y**2 + z**2 + L**2 - l**2) ** 2 - 4 * L**2 * ((x - Rb) ** 2 + z**2)
        scale = (L + l + Rb + np.abs(points).max()) ** 4
        np.testing.assert_allclose(robot.h(points)[:, i], torus, atol=1e-12 * scale)


@pytest.mark.parametrize("leg", [0, 1, 2])
def test_torus_surface_matches_table_4_1(leg):
    """Centre (Rbar cos a, Rbar sin a, 0), axis -sin a x + cos a y, radii L and l: h = 0."""
    robot, alpha = THESIS_DELTA, ALPHA[leg]
    phi, psi = np.meshgrid(np.linspace(-np.pi, np.pi, 25), np.linspace(-np.pi, np.pi, 25))
    radial, axial = robot.L + robot.l * np.cos(phi), robot.l * np.sin(phi)
    u = np.array([np.cos(alpha), np.sin(alpha), 0.0])
    axis = np.array([-np.sin(alpha), np.cos(alpha), 0.0])
    z = np.array([0.0, 0.0, 1.0])
    points = (
        robot.Rbar * u
        + (radial * np.cos(psi))[..., None] * u
        + (radial * np.sin(psi))[..., None] * z
        + axial[..., None] * axis
    )
    np.testing.assert_allclose(robot.h(points)[..., leg], 0.0, atol=1e-14)


@given(st.one_of(rotary_deltas(), linear_deltas()), st.integers(0, 2**32 - 1))
def test_signed_distance_is_one_lipschitz_and_signed_like_h(robot, seed):
    points = _box(robot, 1000, seed)
    sd = robot.signed_distance(points)
    clear = np.abs(sd) > 1e-9
    assert np.array_equal((sd <= 0)[clear], robot.reachable(points)[clear])
    moved = points + np.random.default_rng(seed).normal(scale=0.01, size=points.shape)
    step = np.linalg.norm(moved - points, axis=-1)
    assert np.all(np.abs(robot.signed_distance(moved) - sd) <= step + 1e-12)


def test_margin_shrinks_the_workspace():
    points = _box(THESIS_DELTA, 5000, 3)
    plain = THESIS_DELTA.reachable(points)
    with_margin = THESIS_DELTA.reachable(points, margin=0.01)
    assert with_margin.sum() > 0 and np.all(plain[with_margin]) and with_margin.sum() < plain.sum()


def _reachable_cloud(robot, n=60000, seed=0):
    joints = np.random.default_rng(seed).uniform(-0.7, 1.6, (n, 3))
    points, ok = robot.fk(joints)
    return points[ok]


@pytest.mark.parametrize(
    "goal", [[0.3, 0.0, -0.2], [0.0, 0.0, -0.5], [0.1, -0.25, -0.3], [0.0, 0.0, -0.05]]
)
def test_projection_is_reachable_and_no_farther_than_any_sample(goal):
    goal = np.array(goal)
    assert not THESIS_DELTA.reachable(goal)
    projected, distance = THESIS_DELTA.project(goal)
    assert THESIS_DELTA.ik(projected).ok
    assert distance == pytest.approx(np.linalg.norm(projected - goal))
    nearest_sample = np.linalg.norm(_reachable_cloud(THESIS_DELTA) - goal, axis=-1).min()
    assert distance <= nearest_sample + 1e-6


@pytest.mark.slow
def test_projection_keeps_margin_and_ceiling():
    projected, _ = THESIS_DELTA.project([0.3, 0.0, -0.2], margin=0.01)
    assert THESIS_DELTA.signed_distance(projected) <= -0.01 + 1e-9
    high, _ = THESIS_DELTA.project([0.0, 0.0, 0.05], z_max=-0.1)
    assert high[2] <= -0.1 and THESIS_DELTA.ik(high).ok


def test_projection_leaves_reachable_goals_alone():
    goal = np.array([0.01, 0.02, -0.25])
    projected, distance = THESIS_DELTA.project(goal)
    assert distance == 0.0 and np.array_equal(projected, goal)


def test_projection_of_a_linear_delta():
    robot = LinearDelta(l=0.215, R=0.105, r=0.03)
    projected, distance = robot.project([0.5, 0.0, -0.2])
    assert robot.ik(projected).ok and distance > 0.0
    assert robot.signed_distance(projected) == pytest.approx(0.0, abs=1e-7)


@pytest.mark.parametrize(
    ("goal", "error"),
    [([np.nan, 0, 0], NonFiniteError), ([0, 0], ShapeError), ([[0, 0, -0.2]] * 2, ShapeError)],
)
def test_projection_rejects_bad_goals(goal, error):
    with pytest.raises(error, match="point"):
        THESIS_DELTA.project(goal)


def test_projection_with_an_impossible_margin():
    with pytest.raises(UnreachableError, match="margin"):
        THESIS_DELTA.project([1.0, 0.0, 0.0], margin=1.0)
