"""Round trips between IK and FK, and the leg constraints they must satisfy."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from kinematics import THESIS_DELTA, LinearDelta, RotaryDelta
from tests.support.strategies import per_leg_and_joints, robot_and_joints

# the symmetric robots and the per-leg one (each leg its own geometry): the same laws
FAMILIES = pytest.mark.parametrize(
    "family", [robot_and_joints, per_leg_and_joints], ids=["symmetric", "per-leg"]
)

TOL_M = 1e-9
WELL_CONDITIONED = 1e-3  # dexterity below this amplifies rounding past TOL_M


def _usable(robot, joints):
    """Joint sets with an FK solution away from singularities, the platform below the knees.

    FK returns the sphere intersection below the knees (the working assembly mode); a
    platform above its knees is the other mode, which IK-then-FK cannot give back.
    """
    points, ok = robot.fk(joints)
    below = points[..., 2] < robot.knees(joints)[..., 2].min(axis=-1)
    return ok & below & (np.nan_to_num(robot.dexterity(joints)) > WELL_CONDITIONED)


@pytest.mark.slow
@FAMILIES
@given(data=st.data())
def test_fk_then_ik_with_near_returns_the_joints(family, data):
    robot, joints = data.draw(family())
    points, ok = robot.fk(joints)
    assert points.shape == joints.shape and ok.shape == joints.shape[:-1]
    usable = _usable(robot, joints)
    solved, solved_ok = robot.ik(points, near=joints)
    assert np.all(solved_ok[usable])
    np.testing.assert_allclose(solved[usable], joints[usable], atol=1e-7)


@pytest.mark.slow
@FAMILIES
@given(data=st.data())
def test_ik_then_fk_returns_the_point(family, data):
    robot, joints = data.draw(family())
    points = robot.fk(joints).points
    solved, ok = robot.ik(points)
    assert np.all(ok[_usable(robot, joints)])
    # the knee-out joints may put the knees above this platform: the other assembly mode
    below_solved_knees = points[..., 2] < robot.knees(solved)[..., 2].min(axis=-1)
    usable = _usable(robot, joints) & below_solved_knees
    back, back_ok = robot.fk(solved)
    assert np.all(back_ok[usable])
    np.testing.assert_allclose(back[usable], points[usable], atol=TOL_M)


@given(robot_and_joints())
def test_every_leg_constraint_holds(case):
    robot, joints = case
    points, ok = robot.fk(joints)
    rods = np.linalg.norm(points[..., None, :] - robot.knees(joints), axis=-1)
    np.testing.assert_allclose(rods[ok], robot.l, atol=TOL_M)
    solved = robot.ik(points).joints
    rods = np.linalg.norm(points[..., None, :] - robot.knees(solved), axis=-1)
    np.testing.assert_allclose(rods[ok], robot.l, atol=TOL_M)


@given(robot_and_joints(kind="rotary"))
def test_default_branch_is_knee_out(case):
    """Without ``near``, each leg takes the root with the larger signed reach."""
    robot, joints = case
    points = robot.fk(joints).points
    out = robot.ik(points).joints
    other = np.where(np.isclose(out, joints, atol=1e-7), np.nan, joints)
    # where the random joint was the other root, its reach must be the smaller one
    has_other = np.isfinite(other) & _usable(robot, joints)[..., None]
    assert np.all(np.cos(out[has_other]) >= np.cos(other[has_other]) - 1e-12)


def test_fk_picks_the_solution_below_the_knees():
    points, ok = THESIS_DELTA.fk(np.zeros(3))
    assert ok and points[2] < 0.0
    knees = THESIS_DELTA.knees(np.zeros(3))
    assert points[2] < knees[:, 2].min()


@pytest.mark.parametrize("theta_deg", [66.0, 70.0, 80.0, 88.0])
def test_steep_arms_keep_the_knee_out_root(theta_deg):
    """The knee's plain distance from the axis would pick the inverted root here."""
    robot = RotaryDelta(L=0.2, l=0.25, R=0.05, r=0.0)
    joints = np.full(3, np.radians(theta_deg))
    point = robot.fk(joints).points
    np.testing.assert_allclose(robot.ik(point).joints, joints, atol=1e-9)


def test_g_equal_e_is_no_special_case():
    """G = E makes the quadratic's leading coefficient vanish; theta = pi is a root."""
    robot = RotaryDelta(L=0.1, l=0.25, R=0.05, r=0.0)
    joints = np.array([np.pi, 0.4, 0.4])
    point = robot.fk(joints).points
    solved, ok = robot.ik(point, near=joints)
    assert ok
    np.testing.assert_allclose(np.cos(solved), np.cos(joints), atol=1e-9)
    knee_out = robot.ik(point).joints
    np.testing.assert_allclose(robot.fk(knee_out).points, point, atol=1e-12)


def _other_roots(robot, point, knee_out):
    """The second root of E cos + F sin + G = 0 per leg: roots are phi +- beta."""
    x, y, z = point
    alpha = np.radians([0.0, 120.0, 240.0])
    xi = np.cos(alpha) * x + np.sin(alpha) * y
    E, F = 2 * robot.L * (robot.Rbar - xi), np.full(3, 2 * robot.L * z)
    other = 2 * np.arctan2(F, E) - knee_out
    return np.angle(np.exp(1j * other))  # wrapped to (-pi, pi]


def test_near_picks_smallest_absolute_travel_per_leg():
    point = np.array([0.02, -0.03, -0.22])
    out = THESIS_DELTA.ik(point).joints
    other = _other_roots(THESIS_DELTA, point, out)
    assert np.all(np.abs(other - out) > 1.0)
    np.testing.assert_allclose(THESIS_DELTA.ik(point, near=other).joints, other, atol=1e-12)
    mixed_near = np.array([out[0] + 0.2, other[1] - 0.2, out[2]])
    mixed = THESIS_DELTA.ik(point, near=mixed_near).joints
    np.testing.assert_allclose(mixed, [out[0], other[1], out[2]], atol=1e-12)


def test_near_broadcasts_against_points():
    points = np.array([[0.0, 0.0, -0.25], [0.05, 0.0, -0.2]])
    near = np.zeros(3)
    joints, ok = THESIS_DELTA.ik(points, near=near)
    assert joints.shape == (2, 3) and ok.all()
    np.testing.assert_allclose(joints, THESIS_DELTA.ik(points).joints)


def test_scalar_and_batch_paths_agree():
    rng = np.random.default_rng(1)
    for robot in (THESIS_DELTA, LinearDelta(l=0.215, R=0.105, r=0.03)):
        joints = robot.ik(robot.fk(rng.uniform(-0.2, 0.8, (50, 3))).points).joints
        points = robot.fk(joints).points
        for q, p in zip(joints, points, strict=True):
            np.testing.assert_allclose(robot.ik(p).joints, q, rtol=0, atol=1e-13)
            np.testing.assert_allclose(robot.ik(p, near=q).joints, q, rtol=0, atol=1e-13)
            np.testing.assert_allclose(robot.fk(q).points, p, rtol=0, atol=1e-13)
            np.testing.assert_allclose(robot.ik(tuple(p)).joints, q, rtol=0, atol=1e-13)


def test_thesis_home_pose_by_hand():
    """(0, 0, -0.24): all legs equal; solve E cos + F sin + G = 0 by hand (eq. 3.40)."""
    L, l, Rbar, z = 0.1558, 0.2430, 0.0844 - 0.038, -0.24
    E, F, G = 2 * L * Rbar, 2 * z * L, z * z + Rbar**2 + L**2 - l**2
    # E cos + F sin = rho cos(theta - phi), so theta = phi +- acos(-G / rho)
    phi, beta = np.arctan2(F, E), np.arccos(-G / np.hypot(E, F))
    theta = max(phi + beta, phi - beta, key=np.cos)  # knee out: the larger reach
    joints = THESIS_DELTA.ik([0.0, 0.0, z]).joints
    assert np.allclose(E * np.cos(joints) + F * np.sin(joints) + G, 0.0, atol=1e-15)
    np.testing.assert_allclose(np.cos(joints), np.cos(theta), atol=1e-12)
    assert 0.0 < joints[0] < np.pi / 2


def test_linear_vertical_towers_match_the_printer_formula():
    """Paper eq. 14 with a_i = z: l_1i = z + sqrt(l^2 - dx^2 - dy^2)."""
    robot = LinearDelta(l=0.215, R=0.105, r=0.03)
    point = np.array([0.02, -0.01, -0.15])
    towers = (robot.R - robot.r) * np.array(
        [[1, 0], [-0.5, np.sqrt(3) / 2], [-0.5, -np.sqrt(3) / 2]]
    )
    dx, dy = point[0] - towers[:, 0], point[1] - towers[:, 1]
    expected = point[2] + np.sqrt(robot.l**2 - dx**2 - dy**2)
    np.testing.assert_allclose(robot.ik(point).joints, expected, atol=1e-15)
