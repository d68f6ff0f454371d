"""Units of the loop: timing statistics, following error, the gate's jog clamp, a jog at rest."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from app.config import load_settings
from app.control.errors import GoalRejected
from app.control.gate import Gate
from app.control.safety import FollowingError, MissCounter
from app.control.sources import JogSource, Limits
from app.control.timing import TickClock, TimingRecorder
from kinematics import THESIS_DELTA


def test_timing_statistics_by_hand():
    recorder = TimingRecorder(rate_hz=100.0)  # period 10 ms
    lateness = [0.0, 0.001, 0.002, 0.0005, 0.009]
    work = [0.001, 0.001, 0.001, 0.001, 0.002]  # the last tick overruns: 9 + 2 > 10 ms
    for k, (late, busy) in enumerate(zip(lateness, work, strict=True)):
        recorder.record(k * 0.01, late, busy)
    recorder.refresh()  # the loop refreshes every 0.25 s; these 5 ticks span 40 ms
    window = recorder.last_window()
    assert window.measured_hz == pytest.approx(100.0)
    assert window.worst_ms == pytest.approx(9.0)
    assert window.jitter_p50_ms == pytest.approx(1.0)
    assert window.overruns == 1 and recorder.overruns == 1
    total = recorder.since_start()
    assert total.ticks == 5 and total.jitter_p50_ms == pytest.approx(1.0, abs=0.011)


def test_tick_clock_deadlines_do_not_drift():
    """Deadlines are t0 + k * period: every gap a whole number of periods (a slot missed on a
    loaded machine is skipped, never shifted), however late the ticks ran."""
    clock = TickClock(rate_hz=1000.0, spin_s=0.0)
    deadlines = np.array([clock.wait_next()[0] for _ in range(50)])
    periods = np.diff(deadlines) / 1e-3
    np.testing.assert_allclose(periods, np.round(periods), rtol=0, atol=1e-6)  # float ulps
    assert np.all(np.round(periods) >= 1)


def test_following_error_trips_only_after_its_time():
    detector = FollowingError(limit_rad=0.1, time_s=0.5)
    commanded, lagging, close = np.zeros(3), np.array([0.0, 0.2, 0.0]), np.full(3, 0.05)
    assert detector.check(0.0, commanded, lagging) is None
    assert detector.check(0.4, commanded, lagging) is None
    assert detector.check(0.45, commanded, close) is None  # back under the limit: restart
    assert detector.check(0.6, commanded, lagging) is None
    fault = detector.check(1.11, commanded, lagging)
    assert fault is not None and "joint 2" in fault.reason


def test_miss_counter_counts_consecutive_misses():
    counter = MissCounter(limit=3)
    assert not counter.miss() and not counter.miss()
    counter.ok()
    assert not counter.miss() and not counter.miss() and counter.miss()
    assert counter.total == 5


@pytest.fixture
def gate() -> Gate:
    joints = load_settings().hardware.joints
    return Gate(
        THESIS_DELTA,
        tuple(j.min_angle_rad for j in joints),
        tuple(j.max_angle_rad for j in joints),
        margin_m=0.002,
        z_max_m=-0.06,
        min_dexterity=0.02,
        max_step_rad=0.03,
    )


def test_jog_clamp_stays_on_the_allowed_side(gate):
    start = np.array([0.0, 0.0, -0.22])
    near = THESIS_DELTA.ik(start).joints
    for direction in ([1, 0, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1], [1, 1, -1]):
        clamped = gate.clamp_towards(start, start + np.array(direction), near)
        joints = gate.solve(clamped, near)  # passes every check
        assert gate.inside(clamped) and np.all(np.isfinite(joints))
        assert np.linalg.norm(clamped - start) > 0.02  # it went somewhere


def test_gate_refuses_non_finite_outside_and_joint_limits(gate):
    with pytest.raises(GoalRejected, match="finite"):
        gate.check_point([np.nan, 0, -0.2])
    with pytest.raises(GoalRejected, match="nearest reachable point"):
        gate.check_point([0.4, 0, -0.2])
    with pytest.raises(GoalRejected, match="joint 1"):
        gate.check_joints(np.array([2.0, 0.3, 0.3]))


def test_gate_refuses_joints_too_close_to_a_singularity(gate):
    """Joints inside their limits whose 1/cond(J) is below min_dexterity are refused; the
    gate's own margin is what decides (issue 29, break 05: the check had no test)."""
    joints = np.array([0.3, 0.3, 0.3])  # 1/cond(J) = 0.954
    np.testing.assert_array_equal(gate.check_joints(joints), joints)
    strict = dataclasses.replace(gate, min_dexterity=0.99)
    with pytest.raises(GoalRejected, match="singularity"):
        strict.check_joints(joints)
    with pytest.raises(GoalRejected, match="singularity"):
        strict.solve(THESIS_DELTA.fk(joints).points, joints)


def test_joint_speed_is_limited_per_tick(gate):
    previous = np.zeros(3)
    limited = gate.limit_step(np.array([0.3, -0.06, 0.0]), previous)
    assert np.abs(limited - previous).max() == pytest.approx(0.03)
    np.testing.assert_allclose(limited / np.linalg.norm(limited), [0.98058068, -0.19611614, 0])


def test_a_jog_is_at_rest_only_once_it_stands_at_its_target():
    jog_settings = load_settings().jog
    limits = Limits(
        jog_settings.max_velocity_m_s,
        jog_settings.max_acceleration_m_s2,
        jog_settings.max_jerk_m_s3,
    )
    home, period = np.array([0.0, 0.0, -0.24]), 0.005
    jog = JogSource(home, limits, period)
    assert jog.at_rest
    jog.set_target(home + [0.0, 0.0, 0.005])
    assert not jog.at_rest
    jog.next(period)
    assert not jog.at_rest
    for _ in range(400):
        jog.next(period)
    assert jog.at_rest
    jog.brake()
    assert not jog.at_rest  # braking: its target is wherever it stops
