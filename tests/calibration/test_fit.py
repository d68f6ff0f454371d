"""Plan, fit and validate (app/calibration/fit.py), pairs as CSV (pairs.py), zero ticks
(procedure.offsets_into_zero_ticks): on pairs made by a per-leg model built wrong."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import least_squares

from app.calibration.fit import CalibrationError, fit, plan
from app.calibration.pairs import read_pairs, write_pairs
from app.calibration.procedure import offsets_into_zero_ticks
from hardware.calibration import JointCalibration
from hardware.encoder import RAD_PER_TICK
from kinematics import THESIS_DELTA, PerLegRotaryDelta
from kinematics.identification import Identification, MeasurementFrame

NOMINAL = PerLegRotaryDelta.from_symmetric(THESIS_DELTA)
OFFSETS = tuple(math.radians(d) for d in (2.0, -3.0, 1.5))
FRAME = MeasurementFrame((0.1, -0.05, -0.5), (0.02, -0.01, 1.5))


def measure(robot: PerLegRotaryDelta, joints: np.ndarray, noise_m: float, seed: int = 1):
    """What a motion capture in FRAME sees of ``robot`` at ``joints`` (the encoders' q)."""
    rng = np.random.default_rng(seed)
    return FRAME.from_base(robot.fk(joints).points) + rng.normal(0.0, noise_m, joints.shape)


def test_plan_holds_out_a_quarter_and_reports_observability() -> None:
    chosen = plan(NOMINAL, 24, "offsets")
    assert chosen.fit_joints.shape == (18, 3) and chosen.holdout_joints.shape == (6, 3)
    assert not {tuple(q) for q in chosen.fit_joints} & {tuple(q) for q in chosen.holdout_joints}
    assert chosen.observability.unobservable == () and chosen.observability.condition_number < 20
    geometry = plan(NOMINAL, 24, "geometry")
    assert len(geometry.observability.singular_values) == 18


def test_plan_keeps_to_the_allowed_poses_and_refuses_too_few() -> None:
    chosen = plan(NOMINAL, 16, allowed=lambda q: q[:, 0] < 0.5)
    assert (chosen.joints[:, 0] < 0.5).all()
    with pytest.raises(CalibrationError, match="poses: 5"):
        plan(NOMINAL, 5)
    with pytest.raises(CalibrationError, match="poses"):
        plan(NOMINAL, 16, allowed=lambda q: q[:, 0] < -10)
    with pytest.raises(CalibrationError, match="parameters"):
        plan(NOMINAL, 16, "everything")


def test_offsets_recovered_within_a_tenth_of_a_degree_with_noise() -> None:
    true = NOMINAL.with_values(joint_offsets_rad=OFFSETS)
    chosen = plan(NOMINAL, 30)
    q = chosen.joints
    result = fit(NOMINAL, q, measure(true, q, 3e-4), len(chosen.holdout_joints))
    error_deg = np.degrees(np.subtract(result.robot.joint_offsets_rad, OFFSETS))
    assert np.all(np.abs(error_deg) < 0.1), error_deg
    assert result.holdout_before_m > 3e-3 and result.holdout_rmse_m < 6e-4
    assert result.better
    np.testing.assert_allclose(result.frame.position_m, FRAME.position_m, atol=2e-3)


@pytest.mark.slow
def test_geometry_fit_recovers_rods_off_by_a_millimetre() -> None:
    true = NOMINAL.with_values(joint_offsets_rad=OFFSETS, l=(0.2440, 0.2425, 0.2430))
    chosen = plan(NOMINAL, 60, "geometry")
    q = chosen.joints
    result = fit(NOMINAL, q, measure(true, q, 0.0), len(chosen.holdout_joints), "geometry")
    np.testing.assert_allclose(result.robot.joint_offsets_rad, OFFSETS, atol=1e-5)
    np.testing.assert_allclose(result.robot.l, true.l, atol=1e-6)
    assert result.holdout_rmse_m < 1e-6 < result.holdout_before_m


def test_a_fit_worse_on_held_out_poses_is_not_better() -> None:
    # the held-out poses are exactly what the current model (nominal robot, its frame fitted
    # to the fit poses) predicts: any change the fit makes can only do worse there
    true = NOMINAL.with_values(joint_offsets_rad=OFFSETS)
    chosen = plan(NOMINAL, 24)
    fit_y = measure(true, chosen.fit_joints, 1e-4)
    current = Identification(NOMINAL, FRAME, ("frame_position", "frame_rotation"))
    frame_only = least_squares(
        current.residuals,
        current.initial,
        loss="soft_l1",  # as fit() does
        f_scale=1e-3,
        x_scale="jac",
        args=(chosen.fit_joints, fit_y),
    )
    held_y = current.predict(frame_only.x, chosen.holdout_joints)
    result = fit(NOMINAL, chosen.joints, np.vstack([fit_y, held_y]), len(held_y))
    assert result.holdout_before_m < 1e-5 < result.holdout_rmse_m and not result.better


def test_fit_refuses_bad_pairs() -> None:
    q = plan(NOMINAL, 16).joints
    y = measure(NOMINAL, q, 0.0)
    with pytest.raises(CalibrationError, match="finite"):
        fit(NOMINAL, q, np.where(np.arange(len(q))[:, None] == 3, np.nan, y), 4)
    with pytest.raises(CalibrationError, match="too few"):
        fit(NOMINAL, q[:5], y[:5], 2)
    with pytest.raises(CalibrationError, match=r"\(N, 3\)"):
        fit(NOMINAL, q[:, :2], y, 4)


def test_pairs_round_trip_through_csv(tmp_path) -> None:
    q = plan(NOMINAL, 16).joints
    y = measure(NOMINAL, q, 1e-4)
    write_pairs(tmp_path / "p.csv", q, y, 4)
    pairs = read_pairs(tmp_path / "p.csv")
    np.testing.assert_array_equal(pairs.joints, q)
    np.testing.assert_array_equal(pairs.measured, y)
    assert pairs.holdout == 4


def test_a_csv_without_set_holds_out_every_fourth_row(tmp_path) -> None:
    path = tmp_path / "p.csv"
    rows = ["q0_rad,q1_rad,q2_rad,x_m,y_m,z_m"] + [f"{k},0,0,0,0,{k}" for k in range(8)]
    path.write_text("\n".join(rows) + "\n")
    pairs = read_pairs(path)
    assert pairs.holdout == 2
    np.testing.assert_array_equal(pairs.joints[-2:, 0], [3, 7])


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("q0_rad,q1_rad,x_m,y_m,z_m\n1,2,3,4,5\n", "q2_rad"),
        ("q0_rad,q1_rad,q2_rad,x_m,y_m,z_m\n1,2,3,4,five,6\n", "line 2: y_m = 'five'"),
        ("q0_rad,q1_rad,q2_rad,x_m,y_m,z_m\n1,2,3,4,5,inf\n", "line 2: z_m"),
        ("q0_rad,q1_rad,q2_rad,x_m,y_m,z_m,set\n1,2,3,4,5,6,test\n", "set = 'test'"),
    ],
)
def test_a_bad_csv_names_the_line_and_column(tmp_path, text, message) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(CalibrationError, match=message):
        read_pairs(path)


@pytest.mark.parametrize("direction", [1, -1])
def test_new_zero_ticks_read_the_offset_angles(direction) -> None:
    joints = [JointCalibration(i + 1, 2048 + 10 * i, direction) for i in range(3)]
    moved = offsets_into_zero_ticks(joints, OFFSETS)
    for old, new, offset in zip(joints, moved, OFFSETS, strict=True):
        for ticks in (1500, 2048, 2600):
            assert new.to_rad(ticks) == pytest.approx(old.to_rad(ticks) + offset, abs=RAD_PER_TICK)
