"""The rest-to-rest profile: within its limits, exact at its ends, as fast as ruckig's."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from ruckig import InputParameter, Ruckig, Trajectory

from app.programs.profile import evaluate, rest_to_rest

cases = st.tuples(
    st.floats(1e-4, 0.5),  # distance [m]
    st.floats(0.001, 1.0),  # speed
    st.floats(0.1, 20.0),  # acceleration
    st.floats(1.0, 1000.0),  # jerk
)


def sampled(profile, count=20001):
    tau = np.linspace(0.0, profile.duration, count)
    one = np.ones_like(tau)
    p = profile
    return tau, evaluate(
        tau, p.distance * one, p.speed * one, p.jerk * one, p.tj * one, p.ta * one, p.tv * one
    )


@pytest.mark.slow
@settings(max_examples=60, deadline=None)
@given(cases)
def test_the_profile_keeps_its_limits_and_ends_at_rest_at_the_distance(case):
    distance, speed, accel, jerk = case
    profile = rest_to_rest(distance, speed, accel, jerk)
    tau, (s, v, a, j) = sampled(profile)
    tol = 1e-9
    assert s[0] == 0 and v[0] == 0 and a[0] == 0
    assert s[-1] == pytest.approx(distance, rel=1e-9, abs=1e-12)
    assert abs(v[-1]) < 1e-9 * max(speed, 1) and abs(a[-1]) < 1e-9 * max(accel, 1)
    assert v.max() <= speed * (1 + tol) and np.abs(a).max() <= accel * (1 + tol)
    assert np.abs(j).max() <= jerk * (1 + tol)
    assert (np.diff(s) >= -1e-15).all()  # never backwards


@pytest.mark.slow
@settings(max_examples=30, deadline=None)
@given(cases)
def test_derivatives_are_the_derivatives(case):
    """Finite differences of s, v and a against v, a and j (central, fine grid)."""
    profile = rest_to_rest(*case)
    tau, (s, v, a, j) = sampled(profile, 40001)
    dt = tau[1] - tau[0]
    for lower, higher, scale in ((s, v, case[1]), (v, a, case[2])):
        central = (lower[2:] - lower[:-2]) / (2 * dt)
        # error of a central difference: dt^2/6 times the third derivative, or a jerk
        # switch inside the interval
        bound = case[3] * dt * 2 + 1e-9 * scale
        assert np.abs(central - higher[1:-1]).max() <= bound


def ruckig_duration(distance, speed, accel, jerk):
    inp = InputParameter(1)
    inp.current_position, inp.target_position = [0.0], [distance]
    inp.current_velocity = inp.current_acceleration = [0.0]
    inp.target_velocity = inp.target_acceleration = [0.0]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [speed], [accel], [jerk]
    trajectory = Trajectory(1)
    Ruckig(1).calculate(inp, trajectory)
    return trajectory.duration


@settings(max_examples=60, deadline=None)
@given(cases)
def test_as_fast_as_ruckig(case):
    """Ruckig's rest-to-rest solution is time-optimal: the closed form must match it."""
    assert rest_to_rest(*case).duration == pytest.approx(ruckig_duration(*case), rel=1e-6)


def test_a_zero_distance_takes_no_time_and_bad_limits_are_refused():
    assert rest_to_rest(0.0, 1.0, 1.0, 1.0).duration == 0.0
    with pytest.raises(ValueError, match="speed"):
        rest_to_rest(1.0, 0.0, 1.0, 1.0)
