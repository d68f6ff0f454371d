"""Motor sizing (kinematics/sizing.py): closed-form worst cases against brute force."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from kinematics import THESIS_DELTA
from kinematics.dynamics import THESIS_MASS, inverse_dynamics
from kinematics.sizing import (
    RPM_PER_RAD_S,
    XM430_W210_12V,
    _fibonacci_sphere,
    cone_extremes,
    region_grid,
    size_motors,
)

DOWN = np.array([0.0, 0.0, -1.0])


@given(st.integers(0, 2**32 - 1), st.floats(0.0, np.pi))
def test_cone_extremes_bound_every_direction_and_are_attained(seed, half_angle):
    a = np.random.default_rng(seed).normal(size=(5, 3))
    directions = _fibonacci_sphere(20000)
    inside = directions[np.arccos(np.clip(directions @ DOWN, -1, 1)) <= half_angle]
    inside = np.concatenate([inside, DOWN[None]])
    most, least = cone_extremes(a, DOWN, half_angle)
    dots = a @ inside.T
    assert (dots.max(1) <= most + 1e-12).all() and (dots.min(1) >= least - 1e-12).all()
    slack = 0.03 * np.linalg.norm(a, axis=1)  # the sampling's resolution, ~1.5 deg
    assert (dots.max(1) >= most - slack).all() and (dots.min(1) <= least + slack).all()


def test_static_torque_level_drone_is_the_direct_one():
    grid = region_grid([-0.05, -0.05, -0.28], [0.05, 0.05, -0.2], 4)
    sized = size_motors(THESIS_DELTA, THESIS_MASS, grid, tilt_deg=0.0)
    zero = np.zeros_like(grid)
    direct = inverse_dynamics(THESIS_DELTA, THESIS_MASS.with_payload(0.2), grid, zero, zero)
    assert sized.static_nm.value == pytest.approx(np.abs(direct).max(), rel=1e-9)


def test_worst_cases_bound_brute_force_motions():
    """No sampled gravity, acceleration and velocity beats the reported worst cases."""
    rng = np.random.default_rng(2)
    grid = region_grid([-0.05, -0.05, -0.28], [0.05, 0.05, -0.2], 3)
    sized = size_motors(THESIS_DELTA, THESIS_MASS, grid, tilt_deg=60.0)
    mass = THESIS_MASS.with_payload(0.2)
    n = 4000
    p = grid[rng.integers(0, len(grid), n)]
    tilt = np.radians(60.0) * np.sqrt(rng.uniform(0, 1, n))
    turn = rng.uniform(0, 2 * np.pi, n)
    gravity = 9.81 * np.stack(
        [np.sin(tilt) * np.cos(turn), np.sin(tilt) * np.sin(turn), -np.cos(tilt)], -1
    )
    v = 0.5 * _fibonacci_sphere(n)[rng.permutation(n)]
    a = 4.0 * _fibonacci_sphere(n)[rng.permutation(n)]
    torque = np.abs(inverse_dynamics(THESIS_DELTA, mass, p, v, a, gravity))
    assert torque.max() <= sized.peak_nm.value + 1e-9
    assert torque.max() > 0.6 * sized.peak_nm.value  # the bound is not loose
    static = np.abs(inverse_dynamics(THESIS_DELTA, mass, p, 0 * v, 0 * a, gravity))
    assert static.max() <= sized.static_nm.value + 1e-9
    q = THESIS_DELTA.ik(p).joints
    rpm = np.abs(THESIS_DELTA.joint_velocity(q, v)) * RPM_PER_RAD_S
    assert rpm.max() <= sized.speed_rpm.value + 1e-9


def test_servo_line_and_verdict():
    assert XM430_W210_12V.torque_at(0.0) == pytest.approx(3.0)
    assert XM430_W210_12V.torque_at(38.5) == pytest.approx(1.5)
    assert XM430_W210_12V.torque_at(100.0) == 0.0
    grid = region_grid([-0.05, -0.05, -0.28], [0.05, 0.05, -0.18], 5)
    sized = size_motors(THESIS_DELTA, THESIS_MASS, grid)
    assert sized.passes == (sized.torque_margin >= 1 and sized.speed_margin >= 1)
    assert sized.peak_nm.value > sized.static_nm.value
    heavier = size_motors(THESIS_DELTA, THESIS_MASS, grid, payload_kg=0.5)
    assert heavier.static_nm.value > sized.static_nm.value
