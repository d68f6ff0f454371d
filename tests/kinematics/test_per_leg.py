"""The per-leg rotary Delta: the laws of the symmetric model, and equal legs equal it."""

import math

import numpy as np
import pytest
from hypothesis import given

from kinematics import THESIS_DELTA, InvalidGeometryError, PerLegRotaryDelta, RotaryDelta
from tests.support.strategies import per_leg_and_joints, robot_and_joints

TOL_M = 1e-9
STEP = 1e-6


def _usable(robot, joints, dexterity=1e-3):
    """FK solution away from singularities, the platform below every knee (as the symmetric
    round-trip tests: the other assembly mode cannot come back through IK)."""
    points, ok = robot.fk(joints)
    below = points[..., 2] < robot.knees(joints)[..., 2].min(axis=-1)
    return ok & below & (np.nan_to_num(robot.dexterity(joints)) > dexterity)


# FK(IK) and IK(FK) round trips: tests/kinematics/test_roundtrip.py runs them on this model


@pytest.mark.slow
@given(per_leg_and_joints())
def test_every_leg_keeps_its_own_rod_length(case):
    """|P - C_i| = l_i with C_i built by hand from the docstring's eq. 3.28 and theta = q + o."""
    robot, joints = case
    points, ok = robot.fk(joints)
    theta = joints + np.array(robot.joint_offsets_rad)
    alpha, L = np.array(robot.angles_rad), np.array(robot.L)
    reach = np.array(robot.Rbar) + L * np.cos(theta)
    knees = np.stack([np.cos(alpha) * reach, np.sin(alpha) * reach, -L * np.sin(theta)], -1)
    np.testing.assert_allclose(robot.knees(joints), knees, atol=1e-15)
    rods = np.linalg.norm(points[..., None, :] - knees, axis=-1)
    np.testing.assert_allclose(rods[ok], np.broadcast_to(robot.l, rods.shape)[ok], atol=TOL_M)


@pytest.mark.slow
@given(per_leg_and_joints())
def test_jacobian_matches_finite_differences(case):
    robot, joints = case
    usable = _usable(robot, joints, dexterity=0.02)
    jac = robot.jacobian(joints)
    columns = []
    for j in range(3):
        dq = np.zeros(3)
        dq[j] = STEP
        columns.append((robot.fk(joints + dq).points - robot.fk(joints - dq).points) / (2 * STEP))
    expected = np.stack(columns, axis=-1)
    usable &= np.isfinite(expected).all(axis=(-2, -1))
    scale = np.abs(jac[usable]).max(initial=1.0)
    np.testing.assert_allclose(jac[usable], expected[usable], rtol=1e-4, atol=1e-5 * scale)


@pytest.mark.slow
@given(per_leg_and_joints())
def test_reachable_agrees_with_the_ik(case):
    """margin 0: the per-leg discriminants say exactly where the IK succeeds."""
    robot, joints = case
    points = robot.fk(joints).points + 0.02 * np.sin(joints)  # some in, some out
    np.testing.assert_array_equal(robot.reachable(points), robot.ik(points).ok)


@pytest.mark.slow
@given(robot_and_joints(kind="rotary"))
def test_equal_legs_are_the_symmetric_robot(case):
    robot, joints = case
    same = PerLegRotaryDelta.from_symmetric(robot)
    points, ok = robot.fk(joints)
    got, got_ok = same.fk(joints)
    np.testing.assert_array_equal(got_ok, ok)
    np.testing.assert_allclose(got[ok], points[ok], rtol=0, atol=1e-12)
    for near in (None, joints):
        expected, expected_ok = robot.ik(points, near=near)
        solved, solved_ok = same.ik(points, near=near)
        np.testing.assert_array_equal(solved_ok, expected_ok)
        np.testing.assert_allclose(solved, expected, rtol=0, atol=1e-12, equal_nan=True)
    usable = _usable(robot, joints)
    np.testing.assert_allclose(
        same.jacobian(joints)[usable], robot.jacobian(joints)[usable], rtol=1e-12, atol=1e-12
    )
    np.testing.assert_allclose(same.h(points), robot.h(points), rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(
        same.signed_distance(points), robot.signed_distance(points), atol=1e-12
    )
    for a, b in zip(same.leg_points(joints), robot.leg_points(joints), strict=True):
        np.testing.assert_allclose(a, b, atol=1e-12)


@pytest.mark.slow
@given(robot_and_joints(kind="rotary"))
def test_a_joint_offset_is_a_turned_joint(case):
    """Offsets o: the per-leg FK at q is the symmetric FK at q + o; IK gives back q."""
    robot, joints = case
    offsets = np.array([0.05, -0.03, 0.08])
    turned = PerLegRotaryDelta.from_symmetric(robot, joint_offsets_rad=offsets)
    expected, ok = robot.fk(joints + offsets)
    got, got_ok = turned.fk(joints)
    np.testing.assert_array_equal(got_ok, ok)
    np.testing.assert_allclose(got[ok], expected[ok], atol=1e-12)
    usable = _usable(robot, joints + offsets)
    solved = turned.ik(got, near=joints).joints
    np.testing.assert_allclose(solved[usable], joints[usable], atol=1e-7)


def test_a_longer_rod_moves_the_platform_away_from_its_knee():
    """One rod 1 mm longer: the platform moves about 1 mm, mostly along that rod."""
    joints = np.array([0.4, 0.5, 0.6])
    nominal = THESIS_DELTA.fk(joints).points
    longer = PerLegRotaryDelta.from_symmetric(THESIS_DELTA, l=(0.2440, 0.2430, 0.2430))
    moved = longer.fk(joints).points
    rod = nominal - THESIS_DELTA.knees(joints)[0]
    shift = moved - nominal
    assert 0.5e-3 < np.linalg.norm(shift) < 3e-3
    assert np.dot(shift, rod) > 0.0


@pytest.mark.parametrize(
    ("changes", "field"),
    [
        ({"l": (0.243, 0.1, 0.243)}, "l[1]"),
        ({"L": (0.1558, 0.1558, -0.1)}, "L[2]"),
        ({"r": (0.1, 0.038, 0.038)}, "r[0]"),
        ({"R": (0.0844, math.nan, 0.0844)}, "R[1]"),
        ({"joint_offsets_rad": (0.0, 0.0)}, "joint_offsets_rad"),
        ({"angles_rad": (0.0, "x", 1.0)}, "angles_rad"),
    ],
)
def test_bad_legs_are_refused_by_name(changes, field):
    with pytest.raises(InvalidGeometryError, match=field.replace("[", r"\[")):
        PerLegRotaryDelta.from_symmetric(THESIS_DELTA, **changes)


def test_nominal_is_the_mean_robot():
    robot = PerLegRotaryDelta.from_symmetric(THESIS_DELTA, l=(0.242, 0.243, 0.244))
    assert robot.nominal() == RotaryDelta(L=0.1558, l=0.243, R=0.0844, r=0.038)
