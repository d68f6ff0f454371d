"""Velocity and acceleration kinematics against finite differences."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from kinematics import THESIS_DELTA, RotaryDelta
from tests.support.strategies import robot_and_joints

STEP = 1e-6  # central differences: truncation ~ STEP^2, rounding ~ eps / STEP


def _usable(robot, joints):
    return robot.fk(joints).ok & (np.nan_to_num(robot.dexterity(joints)) > 0.02)


def _fd_jacobian(robot, joints):
    columns = []
    for j in range(3):
        dq = np.zeros(3)
        dq[j] = STEP
        plus, minus = robot.fk(joints + dq).points, robot.fk(joints - dq).points
        columns.append((plus - minus) / (2 * STEP))
    return np.stack(columns, axis=-1)


@pytest.mark.slow
@given(robot_and_joints())
def test_jacobian_matches_finite_differences(case):
    robot, joints = case
    usable = _usable(robot, joints)
    jac = robot.jacobian(joints)
    assert jac.shape == joints.shape + (3,)
    scale = np.abs(jac[usable]).max(initial=1.0)
    expected = _fd_jacobian(robot, joints)
    usable &= np.isfinite(expected).all(axis=(-2, -1))  # the stencil may cross the FK boundary
    # near a singularity the differences' truncation error grows like 1/dexterity^k; a wrong
    # formula is off by O(1), far above this tolerance
    np.testing.assert_allclose(jac[usable], expected[usable], rtol=1e-4, atol=1e-5 * scale)


@given(robot_and_joints(), st.integers(0, 2**32 - 1))
def test_inverse_velocity_inverts_the_jacobian(case, seed):
    robot, joints = case
    usable = _usable(robot, joints)
    qd = np.random.default_rng(seed).normal(size=joints.shape)
    pd = robot.point_velocity(joints, qd)
    np.testing.assert_allclose(robot.joint_velocity(joints, pd)[usable], qd[usable], atol=1e-7)


@pytest.mark.slow
@given(robot_and_joints(shape=()), st.integers(0, 2**32 - 1))
def test_joint_acceleration_matches_a_differentiated_trajectory(case, seed):
    """Along q(t) = q0 + v t + a t^2 / 2, the platform's pd, pdd by differences must map back."""
    robot, q0 = case
    rng = np.random.default_rng(seed)
    # speeds of a robot's own scale: |v|^2 / l comparable to |a| tests the quadratic terms
    v, a = 0.3 * rng.normal(size=3), rng.normal(size=3)
    h = 3e-5  # five-point stencils: truncation ~h^4, rounding ~eps |P| / h^2 ~ 1e-6
    times = h * np.arange(-2.0, 3.0)[:, None]
    points, ok = robot.fk(q0 + v * times + 0.5 * a * times**2)
    # stay clear of the workspace boundary, where the derivatives blow up
    clear = _usable(robot, q0 + v * np.array([[-1e-3], [1e-3]]))
    if not (ok.all() and clear.all() and _usable(robot, q0)):
        return
    pd = (points[0] - 8 * points[1] + 8 * points[3] - points[4]) / (12 * h)
    pdd = (-points[0] + 16 * points[1] - 30 * points[2] + 16 * points[3] - points[4]) / (12 * h**2)
    # differencing error grows with the Jacobian's condition number; a wrong formula is off ~|a|
    scale = (1.0 + np.abs(a).max()) / robot.dexterity(q0)
    np.testing.assert_allclose(robot.joint_acceleration(q0, pd, pdd), a, atol=5e-6 * scale)
    np.testing.assert_allclose(robot.joint_velocity(q0, pd), v, atol=1e-6 * scale)


def test_acceleration_of_a_constant_velocity_line_is_curvature_only():
    """Platform moving in a straight line at constant speed: pdd = 0, yet joints accelerate."""
    start, velocity = np.array([0.0, 0.0, -0.22]), np.array([0.3, 0.1, -0.2])
    h = 1e-4
    q = THESIS_DELTA.ik(start + velocity * np.array([[-h], [0.0], [h]])).joints
    expected = (q[2] - 2 * q[1] + q[0]) / h**2
    got = THESIS_DELTA.joint_acceleration(q[1], velocity, np.zeros(3))
    np.testing.assert_allclose(got, expected, rtol=1e-4, atol=1e-4)


def test_dexterity_is_zero_at_a_stretched_leg_and_high_at_home():
    robot = RotaryDelta(L=0.15, l=0.25, R=0.08, r=0.04)
    home = robot.ik([0.0, 0.0, -0.25]).joints
    assert 0.3 < robot.dexterity(home) <= 1.0
    # leg 1 straight: platform on the circle of radius L + l around the knee circle
    stretched = robot.ik(robot.project([0.45, 0.0, -0.05]).point).joints
    assert robot.dexterity(stretched) < 1e-3


def test_dexterity_nan_where_fk_fails():
    assert not THESIS_DELTA.fk([0.0, 0.0, 3.0]).ok
    assert np.isnan(THESIS_DELTA.dexterity([0.0, 0.0, 3.0]))


def test_jacobian_equals_the_thesis_matrices():
    """J = M^-1 V with M, V written out as in thesis eq. 3.63-3.64 (k_i from eq. 3.57)."""
    robot = THESIS_DELTA
    theta = np.array([0.3, 0.6, 0.1])
    x, y, z = robot.fk(theta).points
    L, l = robot.L, robot.l
    alpha = np.radians([0.0, 120.0, 240.0])
    iy = -np.sin(alpha) * x + np.cos(alpha) * y
    k = np.sqrt(l**2 - iy**2 - (z + L * np.sin(theta)) ** 2)
    s3 = np.sqrt(3.0)
    M = np.array(
        [
            [-k[0], y, L * np.sin(theta[0]) + z],
            [
                (2 * k[1] + 3 * x + s3 * y) / 4,
                (s3 * x + y - 2 * k[1] * s3) / 4,
                L * np.sin(theta[1]) + z,
            ],
            [
                (2 * k[2] + 3 * x - s3 * y) / 4,
                (2 * k[2] * s3 - s3 * x + y) / 4,
                L * np.sin(theta[2]) + z,
            ],
        ]
    )
    V = np.diag(L * (k * np.sin(theta) - (L * np.sin(theta) + z) * np.cos(theta)))
    np.testing.assert_allclose(robot.jacobian(theta), np.linalg.solve(M, V), atol=1e-12)


@pytest.mark.slow
@given(robot_and_joints(shape=(6,)))
def test_one_triple_gives_the_batch_answer(case):
    """The control loop's scalar path (floats, one triple) and the array path agree,
    including where FK fails or M is singular (NaN/inf in both)."""
    robot, joints = case
    batch_jac, batch_dex = robot.jacobian(joints), robot.dexterity(joints)
    for k in range(joints.shape[0]):
        np.testing.assert_allclose(robot.jacobian(joints[k]), batch_jac[k], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(robot.dexterity(joints[k]), batch_dex[k], rtol=1e-9, atol=1e-12)
        assert np.shape(robot.dexterity(list(joints[k]))) == ()
