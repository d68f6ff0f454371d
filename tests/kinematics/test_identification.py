"""Kinematic identification: the measurement model's Jacobian, observability, and fits
that recover a robot built wrong on purpose (scipy's least_squares, as the calibration)."""

import math

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st
from scipy.optimize import least_squares

from kinematics import THESIS_DELTA, InvalidGeometryError, PerLegRotaryDelta, ShapeError
from kinematics.identification import (
    GROUPS,
    Identification,
    MeasurementFrame,
    candidate_poses,
    rpy_matrix,
    select_poses,
)
from tests.support.strategies import per_leg_deltas

NOMINAL = PerLegRotaryDelta.from_symmetric(THESIS_DELTA)
GEOMETRY = ("offsets", "L", "l", "R", "frame_position", "frame_rotation")
# the robot of the goal: offsets of a few degrees, rods and links off by up to 1 mm
TRUE_ROBOT = PerLegRotaryDelta.from_symmetric(
    THESIS_DELTA,
    joint_offsets_rad=np.radians([2.0, -3.0, 1.5]),
    L=(0.1558 + 0.0004, 0.1558 - 0.0006, 0.1558),
    l=(0.2430 + 0.0010, 0.2430 - 0.0007, 0.2430 + 0.0003),
    R=(0.0844 - 0.0005, 0.0844, 0.0844 + 0.0008),
)
TRUE_FRAME = MeasurementFrame((0.25, -0.1, -0.6), (0.02, -0.03, 1.9))


def _fit(ident, joints, measured):
    lower, upper = ident.bounds()
    return least_squares(
        ident.residuals,
        ident.initial,
        jac=lambda p, q, y: ident.jacobian(p, q).reshape(-1, len(p)),
        bounds=(lower, upper),
        loss="soft_l1",
        f_scale=1e-3,
        x_scale="jac",
        xtol=1e-15,
        ftol=1e-15,
        gtol=1e-15,
        args=(joints, measured),
    )


def _offsets(ident, params):
    robot, _ = ident.unpack(params)
    return np.array(robot.joint_offsets_rad)


@pytest.mark.slow
@given(
    per_leg_deltas(),
    st.integers(0, 2**32 - 1),
    st.sampled_from([GROUPS, GEOMETRY, ("offsets", "frame_rotation"), ("l", "angles")]),
)
def test_jacobian_matches_finite_differences(robot, seed, groups):
    rng = np.random.default_rng(seed)
    robot = robot.with_values(r=tuple(max(v, 1e-3) for v in robot.r))  # r - h stays >= 0
    frame = MeasurementFrame(tuple(rng.uniform(-0.5, 0.5, 3)), tuple(rng.uniform(-3, 3, 3)))
    ident = Identification(robot, frame, groups)
    params = ident.initial
    joints = candidate_poses(robot, 30, min_dexterity=0.05, seed=seed)
    assume(len(joints) > 0)  # a random design may have no well-conditioned pose in range
    jac = ident.jacobian(params, joints)
    assert jac.shape == (len(joints), 3, len(params))
    h = 1e-6
    for k in range(len(params)):
        step = np.zeros_like(params)
        step[k] = h
        fd = (ident.predict(params + step, joints) - ident.predict(params - step, joints)) / (2 * h)
        # a central difference's truncation error grows with the curvature of a small,
        # sharply bent design (seen: 5e-7 of 2.9); a wrong term is of the order of 1
        np.testing.assert_allclose(jac[..., k], fd, atol=1e-6 * max(1.0, np.abs(jac).max()))


def test_the_prediction_is_the_fk_seen_from_the_frame():
    joints = candidate_poses(TRUE_ROBOT, 50)
    ident = Identification(NOMINAL, TRUE_FRAME, GROUPS)
    params = ident.vector(TRUE_ROBOT, TRUE_FRAME)
    points = TRUE_ROBOT.fk(joints).points
    predicted = ident.predict(params, joints)
    # by hand: y = Rm^T (P - t), Rm = Rz Ry Rx
    (roll, pitch, yaw), t = TRUE_FRAME.rpy_rad, np.array(TRUE_FRAME.position_m)
    cr, sr, cp, sp, cy, sy = (f(a) for a in (roll, pitch, yaw) for f in (math.cos, math.sin))
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    np.testing.assert_allclose(rpy_matrix(TRUE_FRAME.rpy_rad), rz @ ry @ rx, atol=1e-15)
    expected = np.einsum("ji,nj->ni", rz @ ry @ rx, points - t)  # Rm^T (P - t) per row
    np.testing.assert_allclose(predicted, expected, atol=1e-15)
    np.testing.assert_allclose(TRUE_FRAME.to_base(predicted), points, atol=1e-15)
    robot, frame = ident.unpack(params)
    assert robot == TRUE_ROBOT and frame == TRUE_FRAME


def test_offsets_and_frame_are_observable_from_selected_poses():
    ident = Identification(NOMINAL, groups=("offsets", "frame_position", "frame_rotation"))
    chosen = select_poses(ident, 30)
    report = ident.observability(ident.initial, chosen)
    assert report.unobservable == () and report.combinations == ()
    assert len(report.singular_values) == 9 and report.condition_number < 20
    # greedy selection beats the same number of random safe poses
    random = candidate_poses(NOMINAL, 200, seed=7)[:30]
    assert report.condition_number < ident.observability(ident.initial, random).condition_number


@pytest.mark.slow
def test_what_no_data_can_see_is_named():
    """Only R_i - r_i enters the model; a common turn of the legs is a turn of the frame."""
    ident = Identification(NOMINAL, groups=GROUPS)
    joints = select_poses(ident, 40)
    report = ident.observability(ident.initial, joints)
    assert {f"{g}[{i}]" for g in ("R", "r") for i in range(3)} <= set(report.unobservable)
    assert {"frame_rotation[2]", "angles[0]"} <= set(report.unobservable)
    assert math.isinf(report.condition_number) or report.condition_number > 1e8
    assert "offsets[0]" not in report.unobservable and "l[1]" not in report.unobservable
    # the directions are truly blind: R_0 and r_0 up together moves no prediction
    jac = ident.jacobian(ident.initial, joints)
    names = ident.names
    both = np.zeros(len(names))
    both[names.index("R[0]")] = both[names.index("r[0]")] = 1.0
    np.testing.assert_allclose(jac @ both, 0.0, atol=1e-15)
    turn = np.zeros(len(names))
    turn[[names.index(f"angles[{i}]") for i in range(3)]] = 1.0
    turn[names.index("frame_rotation[2]")] = 1.0
    np.testing.assert_allclose(jac @ turn, 0.0, atol=1e-12)


@pytest.mark.slow
def test_an_exact_fit_recovers_offsets_geometry_and_frame():
    """No noise: bounded robust least squares from the nominal robot finds the truth."""
    ident = Identification(NOMINAL, groups=GEOMETRY)
    joints = select_poses(ident, 30)
    measured = TRUE_FRAME.from_base(TRUE_ROBOT.fk(joints).points)
    before = np.sqrt(np.mean(ident.residuals(ident.initial, joints, measured) ** 2))
    assert before > 1e-3  # several millimetres off before
    result = _fit(ident, joints, measured)
    np.testing.assert_allclose(_offsets(ident, result.x), TRUE_ROBOT.joint_offsets_rad, atol=1e-6)
    robot, frame = ident.unpack(result.x)
    for name in ("L", "l", "R"):
        np.testing.assert_allclose(getattr(robot, name), getattr(TRUE_ROBOT, name), atol=1e-7)
    np.testing.assert_allclose(frame.position_m, TRUE_FRAME.position_m, atol=1e-7)
    assert np.sqrt(np.mean(result.fun**2)) < 1e-9


def test_offsets_within_a_tenth_of_a_degree_from_noisy_poses():
    """0.3 mm noise, 30 selected poses, fitting offsets and the frame."""
    true_robot = NOMINAL.with_values(joint_offsets_rad=tuple(np.radians([2.0, -3.0, 1.5])))
    ident = Identification(NOMINAL, groups=("offsets", "frame_position", "frame_rotation"))
    joints = select_poses(ident, 30)
    rng = np.random.default_rng(20)
    measured = TRUE_FRAME.from_base(true_robot.fk(joints).points)
    measured += rng.normal(0.0, 3e-4, measured.shape)
    result = _fit(ident, joints, measured)
    error = _offsets(ident, result.x) - true_robot.joint_offsets_rad
    assert np.all(np.abs(np.degrees(error)) < 0.1), np.degrees(error)
    assert np.sqrt(np.mean(result.fun**2)) < 4e-4  # the noise, no more


@pytest.mark.slow
def test_noisy_geometry_fit_is_as_good_as_its_observability_says():
    """Rods off by up to 1 mm: fitting the geometry too, the offsets' errors stay within
    4 predicted standard deviations and the held-out RMSE is under 0.5 mm."""
    ident = Identification(NOMINAL, groups=GEOMETRY)
    joints = select_poses(ident, 40)
    rng = np.random.default_rng(21)
    measured = TRUE_FRAME.from_base(TRUE_ROBOT.fk(joints).points)
    measured += rng.normal(0.0, 3e-4, measured.shape)
    result = _fit(ident, joints, measured)
    sd = ident.observability(result.x, joints).standard_deviations(3e-4)
    error = _offsets(ident, result.x) - TRUE_ROBOT.joint_offsets_rad
    assert np.all(np.abs(error) < 4 * np.array([sd[f"offsets[{i}]"] for i in range(3)]))
    held_out = candidate_poses(NOMINAL, 200, seed=99)
    truth = TRUE_FRAME.from_base(TRUE_ROBOT.fk(held_out).points)
    truth += rng.normal(0.0, 3e-4, truth.shape)
    # before: the nominal robot, even with the frame known; after: near the noise (0.3 mm)
    nominal = ident.vector(NOMINAL, TRUE_FRAME)
    before = np.sqrt(np.mean(ident.residuals(nominal, held_out, truth) ** 2))
    after = np.sqrt(np.mean(ident.residuals(result.x, held_out, truth) ** 2))
    assert before > 3e-3 and after < 4e-4, (before, after)


def test_bounds_keep_fits_physical():
    ident = Identification(NOMINAL, groups=("offsets", "l", "r"))
    lower, upper = ident.bounds({"l": 0.002})
    np.testing.assert_allclose(upper[3:6] - lower[3:6], 0.004)
    assert np.all(lower[6:] >= 0.0) and np.all(lower[:3] < ident.initial[:3])


def test_bad_requests_are_refused_by_name():
    with pytest.raises(InvalidGeometryError, match="groups"):
        Identification(NOMINAL, groups=("offsets", "wheels"))
    ident = Identification(NOMINAL)
    with pytest.raises(ShapeError, match="params"):
        ident.predict(np.zeros(4), np.zeros((2, 3)))
    with pytest.raises(ShapeError, match="joints"):
        ident.predict(ident.initial, np.zeros(3))
    with pytest.raises(ShapeError, match="count"):
        select_poses(ident, 5, candidates=np.zeros((2, 3)))
    with pytest.raises(InvalidGeometryError, match=r"l\[0\]"):
        Identification(NOMINAL, groups=("l",)).predict([0.1, 0.243, 0.243], np.zeros((1, 3)))
