"""project(): the nearest admissible point, as laws (issue 15, part 1).

Admissible: every leg reaches with ``margin`` to spare (``signed_distance <= -margin``),
the IK accepts it, and z <= z_max. The laws: the answer is admissible; no admissible
point is nearer the goal by more than TOLERANCE (dense samples in the ball around the goal
and FK clouds); nothing admissible lies just past the answer towards the goal; projecting
the answer again leaves it alone.
"""

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from kinematics import THESIS_DELTA, LinearDelta, RotaryDelta, UnreachableError
from tests.support.strategies import joint_range, linear_deltas, rotary_deltas

TOLERANCE = 1e-4  # [m]: the accuracy project() states


def _admissible(robot, points, margin, z_max):
    points = np.asarray(points, dtype=float)
    ok = robot.ik(points).ok & (robot.signed_distance(points) <= -margin)
    return ok if z_max is None else ok & (points[..., 2] <= z_max)


def _fk_cloud(robot, count, seed):
    low, high = joint_range(robot)
    points, ok = robot.fk(np.random.default_rng(seed).uniform(low, high, (count, 3)))
    return points[ok]


def _assert_nearest(robot, goal, margin=0.0, z_max=None, samples=60_000, seed=0):
    """The laws for one goal; returns the projection."""
    goal = np.asarray(goal, dtype=float)
    point, distance = robot.project(goal, margin=margin, z_max=z_max)
    assert _admissible(robot, point, margin, z_max), (goal, point)
    assert distance == pytest.approx(np.linalg.norm(point - goal), abs=1e-12)
    if distance == 0.0:
        return point, distance
    # Nothing admissible just past the answer towards the goal (else it was not nearest).
    toward = (goal - point) / distance
    assert not _admissible(robot, point + 1e-6 * toward, margin, z_max)
    # Nothing admissible nearer than distance - TOLERANCE: a dense ball and an FK cloud.
    rng = np.random.default_rng(seed)
    direction = rng.normal(size=(samples, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    radius = (distance - TOLERANCE) * rng.uniform(0.0, 1.0, (samples, 1)) ** (1.0 / 3.0)
    ball = goal + radius * direction
    assert not _admissible(robot, ball, margin, z_max).any(), (goal, point, distance)
    cloud = _fk_cloud(robot, samples, seed)
    cloud = cloud[_admissible(robot, cloud, margin, z_max)]
    if len(cloud):
        assert np.linalg.norm(cloud - goal, axis=1).min() >= distance - TOLERANCE
    # Projecting the answer again leaves it where it is.
    again, moved = robot.project(point, margin=margin, z_max=z_max)
    assert moved == 0.0 and np.array_equal(again, point)
    return point, distance


# ---- the inputs ----


def test_thesis_robot_above_the_base_gets_the_near_side():
    """Issue 15: 0.102 m came back; (0.155, 0.190, 0.064) is reachable 0.048 m away."""
    goal = np.array([0.2, 0.2, 0.05])
    known = np.array([0.155, 0.190, 0.064])
    assert THESIS_DELTA.ik(known).ok
    point, distance = _assert_nearest(THESIS_DELTA, goal)
    assert distance <= np.linalg.norm(known - goal)  # 0.0482 m
    assert distance == pytest.approx(0.0476, abs=5e-4)
    assert point[2] > 0.0  # the arms reach up past the base plane, as the known point does


def test_vertical_rails_keep_the_height():
    """Reach on vertical rails does not depend on z: only x, y move.

    Rails at Rbar = 0.1 m, discs of radius l = 0.2 m about them in x, y: the disc about
    rail 1 at (0.1, 0) ends at x = -0.1, and (-0.1, 0) is 0.1 m from rails 2 and 3.
    """
    robot = LinearDelta(l=0.2, R=0.1, r=0.0)
    point, distance = _assert_nearest(robot, [-0.5, 0.0, -0.05])
    np.testing.assert_allclose(point, [-0.1, 0.0, -0.05], atol=1e-8)
    assert distance == pytest.approx(0.4, abs=1e-8)


@pytest.mark.parametrize(
    "goal",
    [
        [0.2, 0.2, 0.05],
        [0.3, 0.0, -0.2],
        [-0.25, 0.1, -0.1],
        [0.0, 0.0, 0.0],
        [0.05, -0.3, -0.45],
        [0.0, 0.0, -0.6],
        [0.18, 0.0, -0.07],
    ],
)
def test_thesis_robot_with_the_servers_margin_and_ceiling(goal):
    """As the server and the jog clamp call it: margin 2 mm, ceiling -0.06 m."""
    point, _ = _assert_nearest(THESIS_DELTA, goal, margin=0.002, z_max=-0.06)
    assert point[2] <= -0.06


@pytest.mark.parametrize("incline_deg", [35.0, 60.0, 90.0])
def test_linear_delta_with_margin_and_ceiling(incline_deg):
    robot = LinearDelta(l=0.215, R=0.105, r=0.03, incline=math.radians(incline_deg))
    for goal in ([0.5, 0.0, -0.2], [-0.2, 0.3, -0.26], [0.0, 0.0, 0.1], [0.1, -0.1, -0.6]):
        _assert_nearest(robot, goal, margin=0.002, z_max=-0.06)


# ---- the laws on random robots, margins, ceilings and goals ----


@st.composite
def problems(draw):
    """(robot, goal, margin, z_max): a goal near the workspace, sometimes far from it."""
    robot = draw(st.one_of(rotary_deltas(), linear_deltas()))
    seed = draw(st.integers(0, 2**32 - 1))
    cloud = _fk_cloud(robot, 4000, seed)
    assume(len(cloud) > 0)
    rng = np.random.default_rng(seed)
    margin = draw(st.sampled_from([0.0, 0.002, 0.02 * robot.l]))
    z_max = None
    if draw(st.booleans()):
        z_max = float(np.quantile(cloud[:, 2], draw(st.floats(0.2, 1.0))))
    scale = draw(st.sampled_from([0.003, 0.03, 0.3]))
    goal = cloud[rng.integers(len(cloud))] + rng.normal(scale=scale, size=3)
    return robot, goal, margin, z_max


@pytest.mark.slow
@settings(max_examples=30, deadline=None)
@given(problems())
def test_projection_is_the_nearest_admissible_point(problem):
    robot, goal, margin, z_max = problem
    _assert_nearest(robot, goal, margin, z_max, samples=30_000)


@pytest.mark.slow
def test_rotary_delta_with_a_ring_torus_margin():
    """A margin that leaves the tube thinner than the upper link (a ring torus)."""
    robot = RotaryDelta(L=0.1, l=0.12, R=0.1, r=0.02)
    for goal in ([0.3, 0.0, -0.1], [0.0, 0.0, -0.3], [0.05, 0.1, 0.02]):
        _assert_nearest(robot, goal, margin=0.03)


def test_nothing_admissible_is_an_error_naming_the_margin():
    with pytest.raises(UnreachableError, match="margin"):
        THESIS_DELTA.project([0.3, 0.0, -0.2], margin=0.3)
    with pytest.raises(UnreachableError, match="margin"):
        LinearDelta(l=0.2, R=0.1, r=0.0).project([0.3, 0.0, -0.2], margin=0.25)
