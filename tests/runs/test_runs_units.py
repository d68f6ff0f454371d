"""Run maths: statistics by hand, plan continuity, whole-path feasibility, logs."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from mcap.reader import make_reader

from app.config import load_settings
from app.control.errors import GoalRejected
from app.control.gate import Gate
from app.runs.feasibility import check_path
from app.runs.logs import COLUMNS, RunLog, read_messages
from app.runs.paths import ChirpParams, WaypointParams
from app.runs.stats import axis_stats, error_stats
from app.runs.trajectories import SinusoidParams, plan_sinusoid
from kinematics import THESIS_DELTA


def test_axis_stats_by_hand():
    stats = axis_stats(np.array([0.001, -0.001, 0.003, 0.02]))
    assert stats["mean_m"] == pytest.approx(0.00575)
    assert stats["rmse_m"] == pytest.approx(np.sqrt((1 + 1 + 9 + 400) / 4) * 1e-3)
    assert stats["std_m"] == pytest.approx(
        np.sqrt(
            (
                (0.001 - 0.00575) ** 2
                + (-0.001 - 0.00575) ** 2
                + (0.003 - 0.00575) ** 2
                + (0.02 - 0.00575) ** 2
            )
            / 4
        )
    )
    assert stats["max_abs_m"] == pytest.approx(0.02)
    assert stats["share_under_1cm"] == 0.75 and stats["share_under_1mm"] == 0.0


@given(st.lists(st.floats(-0.1, 0.1), min_size=1, max_size=200))
def test_rmse_squared_is_mean_squared_plus_variance(errors):
    stats = axis_stats(np.array(errors))
    assert stats["rmse_m"] ** 2 == pytest.approx(
        stats["mean_m"] ** 2 + stats["std_m"] ** 2, rel=1e-9, abs=1e-15
    )


def test_error_stats_per_axis_and_mask():
    goal = np.zeros((4, 3))
    measured = np.array([[0.0, 0.0, 0.1], [0.001, 0.0, 0.0], [0.001, 0.0, 0.0], [0, 0, 0]])
    stats = error_stats(goal, measured, mask=np.array([False, True, True, True]))
    assert stats["samples"] == 3 and stats["z"]["max_abs_m"] == 0.0
    assert stats["x"]["mean_m"] == pytest.approx(-0.002 / 3)


def test_plan_is_continuous_in_position_velocity_and_acceleration():
    params = SinusoidParams(duration_s=2.0)
    plan = plan_sinusoid(params, np.array([0.02, -0.01, -0.22]))
    dt = 1e-4
    times, points = plan.sample(dt)
    velocity = np.diff(points, axis=0) / dt
    acceleration = np.diff(velocity, axis=0) / dt
    speed, accel, _ = params.peaks()
    # no step anywhere: the largest change per sample stays within the plan's own limits
    assert np.abs(velocity).max() <= speed * 1.01
    assert np.abs(acceleration).max() <= accel * 1.01
    np.testing.assert_allclose(points[0], [0.02, -0.01, -0.22], atol=1e-12)
    np.testing.assert_allclose(np.abs(velocity[-1]), 0.0, atol=accel * dt * 2)
    start = plan.approach_s
    np.testing.assert_allclose(plan.point_at(start + 0.3), params.derivatives(np.array(0.3), 0))


def _gate() -> Gate:
    joints = load_settings().hardware.joints
    return Gate(
        THESIS_DELTA,
        tuple(j.min_angle_rad for j in joints),
        tuple(j.max_angle_rad for j in joints),
        0.002,
        -0.06,
        0.02,
        7.5 * 0.005,
    )


def test_thesis_sinusoid_is_feasible_and_a_large_one_is_not():
    gate, start = _gate(), np.array([0.0, 0.0, -0.24])
    near = THESIS_DELTA.ik(start).joints
    times, points = plan_sinusoid(SinusoidParams(), start).sample(0.005)
    check_path(gate, times, points, near)
    times, points = plan_sinusoid(SinusoidParams(amplitude_m=(0.2, 0.05, 0.08)), start).sample(
        0.005
    )
    with pytest.raises(GoalRejected, match=r"outside the workspace at t = \d+\.\d+ s"):
        check_path(gate, times, points, near)


def test_from_a_hanging_arm_the_refusal_says_to_move_it_in_first():
    """Torque on with the arm hanging straight down (theta = 90 deg, below the workspace's
    margin): the approach's first point is the robot itself, and the error says so."""
    gate, hanging = _gate(), np.full(3, np.pi / 2)
    start = THESIS_DELTA.fk(hanging).points
    times, points = plan_sinusoid(SinusoidParams(), start).sample(0.005)
    with pytest.raises(GoalRejected, match=r"at t = 0\.000 s.*move it into the workspace first"):
        check_path(gate, times, points, hanging)
    times, points = plan_sinusoid(
        SinusoidParams(amplitude_m=(0.2, 0.05, 0.08)), np.array([0.0, 0.0, -0.24])
    ).sample(0.005)
    with pytest.raises(GoalRejected) as refused:  # later points: no such advice
        check_path(gate, times, points, THESIS_DELTA.ik([0.0, 0.0, -0.24]).joints)
    assert "first" not in str(refused.value)


def test_too_fast_for_the_joints_is_refused():
    gate, start = _gate(), np.array([0.0, 0.0, -0.24])
    fast = SinusoidParams(amplitude_m=(0.0, 0.0, 0.05), frequency_hz=(0.0, 0.0, 6.0))
    times, points = plan_sinusoid(fast, start).sample(0.005)
    with pytest.raises(GoalRejected, match="joint speed"):
        check_path(gate, times, points, THESIS_DELTA.ik(start).joints)


def _row(t: float) -> dict:
    row = dict.fromkeys(COLUMNS)
    row.update({"t_s": t, "phase": "timed", "mode": "test", "goal_x_m": t})
    return row


def test_logs_are_readable_finished_and_cut_short(tmp_path):
    log = RunLog(tmp_path / "run", {"run_id": "x"})
    for k in range(500):
        log.write(_row(k * 0.005))
    log._flush()
    shutil.copy(log.mcap_path, tmp_path / "crashed.mcap")  # what a crash would leave
    log.close()
    with open(log.mcap_path, "rb") as file:
        assert sum(1 for _ in make_reader(file).iter_messages()) == 500
    crashed = read_messages(tmp_path / "crashed.mcap")
    assert len(crashed) == 500 and crashed[-1]["goal_x_m"] == pytest.approx(499 * 0.005)
    lines = log.csv_path.read_text().splitlines()
    assert lines[0].split(",") == COLUMNS and len(lines) == 501


@pytest.mark.parametrize(
    "path",
    [
        SinusoidParams(phase_rad=(0.3, 1.0, -0.5)),
        ChirpParams(axis=0, f0_hz=0.5, f1_hz=2.5, duration_s=4.0),
        WaypointParams(((0, 0, -0.22), (0.05, 0, -0.22), (0.05, 0.04, -0.26)), (0.0, 1.0, 2.5)),
    ],
)
def test_path_derivatives_match_differences(path):
    """Every timed path's velocity and acceleration are the derivatives of its position."""
    t = np.linspace(0.0, path.duration_s, 40001)
    dt = t[1] - t[0]
    position, velocity, acceleration = (path.derivatives(t, k) for k in range(3))
    speed, accel, _ = path.peaks()
    np.testing.assert_allclose(
        np.gradient(position, dt, axis=0)[1:-1], velocity[1:-1], atol=1e-5 * max(speed, 1)
    )
    np.testing.assert_allclose(
        np.gradient(velocity, dt, axis=0)[1:-1], acceleration[1:-1], atol=1e-4 * max(accel, 1)
    )
    assert np.abs(velocity).max() <= speed * (1 + 1e-6)
    assert np.abs(acceleration).max() <= accel * (1 + 1e-3)


def test_waypoints_rest_at_each_point_and_reject_bad_timing():
    path = WaypointParams(((0, 0, -0.2), (0.02, 0, -0.2), (0.02, 0.02, -0.2)), (0.0, 0.5, 1.0))
    for t, point in zip(path.times_s, path.points_m, strict=True):
        np.testing.assert_allclose(path.derivatives(np.array(t), 0), point, atol=1e-15)
        np.testing.assert_allclose(path.derivatives(np.array(t), 1), 0.0, atol=1e-12)
    with pytest.raises(ValueError, match="times_s"):
        WaypointParams(((0, 0, -0.2), (0.02, 0, -0.2)), (0.0, 0.0))
