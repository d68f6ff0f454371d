"""PerLegRotaryDelta.project: the nearest admissible point of a robot whose legs differ.

The same laws as tests/kinematics/test_projection.py: the answer is admissible (the IK
accepts it, every leg has ``margin`` to spare, z <= z_max); no admissible point is nearer
the goal by more than TOLERANCE (a dense ball about the goal and an FK cloud); nothing
admissible lies just past the answer towards the goal; projecting it again leaves it
alone. And the special cases: equal legs give the symmetric robot's answer, and joint
offsets (which only relabel the joints) change nothing.
"""

from __future__ import annotations

import numpy as np
import pytest

from kinematics import THESIS_DELTA, PerLegRotaryDelta, UnreachableError

TOLERANCE = 1e-4  # [m]: the accuracy project() states
EQUAL = PerLegRotaryDelta.from_symmetric(THESIS_DELTA)
WRONG = PerLegRotaryDelta.from_symmetric(
    THESIS_DELTA,
    joint_offsets_rad=np.radians([3.0, -2.0, 2.5]),
    L=(0.150, 0.1558, 0.162),
    l=(0.236, 0.243, 0.252),
    R=(0.0844, 0.090, 0.080),
    r=(0.038, 0.035, 0.040),
    angles_rad=np.radians([2.0, 118.0, 243.0]),
)
GOALS = [
    (0.0, 0.0, 0.05),  # above the base
    (0.0, 0.0, -0.6),  # below the reach
    (0.4, 0.1, -0.25),  # far out to the side
    (-0.3, -0.3, -0.1),
    (0.05, -0.02, -0.12),  # up under the base, inside the ring of motors
]


def _admissible(robot, points, margin, z_max):
    points = np.asarray(points, dtype=float)
    ok = robot.ik(points).ok & (robot.signed_distance(points) <= -margin)
    return ok if z_max is None else ok & (points[..., 2] <= z_max)


def _assert_nearest(robot, goal, margin=0.0, z_max=None, samples=40_000, seed=0):
    goal = np.asarray(goal, dtype=float)
    point, distance = robot.project(goal, margin=margin, z_max=z_max)
    assert _admissible(robot, point, margin, z_max), (goal, point)
    assert distance == pytest.approx(np.linalg.norm(point - goal), abs=1e-12)
    if distance == 0.0:
        return point, distance
    toward = (goal - point) / distance
    assert not _admissible(robot, point + 1e-6 * toward, margin, z_max)
    rng = np.random.default_rng(seed)
    direction = rng.normal(size=(samples, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    radius = (distance - TOLERANCE) * rng.uniform(0.0, 1.0, (samples, 1)) ** (1.0 / 3.0)
    assert not _admissible(robot, goal + radius * direction, margin, z_max).any()
    cloud, ok = robot.fk(rng.uniform(-0.6, 1.5, (samples, 3)))
    cloud = cloud[ok]
    cloud = cloud[_admissible(robot, cloud, margin, z_max)]
    if len(cloud):
        assert np.linalg.norm(cloud - goal, axis=1).min() >= distance - TOLERANCE
    again, moved = robot.project(point, margin=margin, z_max=z_max)
    assert moved == 0.0 and np.array_equal(again, point)
    return point, distance


@pytest.mark.slow
@pytest.mark.parametrize("goal", GOALS)
def test_equal_legs_project_as_the_symmetric_robot(goal) -> None:
    for margin, z_max in ((0.0, None), (0.01, -0.05)):
        mine = EQUAL.project(goal, margin=margin, z_max=z_max)
        theirs = THESIS_DELTA.project(goal, margin=margin, z_max=z_max)
        np.testing.assert_allclose(mine.point, theirs.point, atol=1e-12)


@pytest.mark.parametrize("goal", GOALS)
@pytest.mark.parametrize(("margin", "z_max"), [(0.0, None), (0.01, -0.05)])
def test_a_robot_with_unequal_legs_gets_the_nearest_admissible_point(goal, margin, z_max):
    _assert_nearest(WRONG, goal, margin, z_max)


@pytest.mark.slow
def test_joint_offsets_do_not_move_the_workspace() -> None:
    plain = WRONG.with_values(joint_offsets_rad=(0.0, 0.0, 0.0))
    for goal in GOALS:
        np.testing.assert_allclose(
            WRONG.project(goal, margin=0.005).point, plain.project(goal, margin=0.005).point
        )


def test_a_reachable_goal_comes_back_unchanged() -> None:
    goal = WRONG.fk(np.radians([30.0, 40.0, 35.0])).points
    point, distance = WRONG.project(goal)
    assert distance == 0.0 and np.array_equal(point, goal)


def test_no_admissible_point_is_an_error_naming_the_margin() -> None:
    with pytest.raises(UnreachableError, match="margin"):
        WRONG.project((0.0, 0.0, -0.3), margin=0.2)
