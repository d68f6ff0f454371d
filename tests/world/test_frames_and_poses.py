"""Drone frames (NED/FRD to world/FLU), pose vetting, prediction."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from app.world.frames import attitude_ned_frd_to_enu_flu, frd_to_flu, ned_to_enu
from app.world.hold import angular_velocity, predict
from app.world.poses import PoseTracker, make_sample
from kinematics import Pose, PoseError
from kinematics.pose import quaternion_to_matrix

H = math.sqrt(0.5)


def test_ned_positions_and_frd_rates_by_hand():
    np.testing.assert_allclose(ned_to_enu([1.0, 2.0, -3.0]), [2.0, 1.0, 3.0])  # 3 m up
    np.testing.assert_allclose(frd_to_flu([0.1, 0.2, 0.3]), [0.1, -0.2, -0.3])


@pytest.mark.parametrize(
    ("q_ned_frd", "forward", "left"),
    [
        ([1.0, 0.0, 0.0, 0.0], [0, 1, 0], [-1, 0, 0]),  # facing north
        ([H, 0.0, 0.0, H], [1, 0, 0], [0, 1, 0]),  # yawed +90 (clockwise from above): east
        ([H, H, 0.0, 0.0], [0, 1, 0], [0, 0, 1]),  # facing north, rolled right 90: left is up
    ],
)
def test_attitudes_map_the_body_axes(q_ned_frd, forward, left):
    rotation = quaternion_to_matrix(attitude_ned_frd_to_enu_flu(np.array(q_ned_frd)))
    np.testing.assert_allclose(rotation @ [1, 0, 0], forward, atol=1e-12)
    np.testing.assert_allclose(rotation @ [0, 1, 0], left, atol=1e-12)


def _sample(t, x=0.0, q=(1.0, 0.0, 0.0, 0.0)):
    return make_sample(t, [x, 0.0, 1.0], q, received_s=0.0)


def test_tracker_drops_old_duplicate_and_jumping_samples():
    tracker = PoseTracker(stale_after_s=0.05, lost_after_s=0.5, max_jump_m=0.05)
    assert tracker.push(_sample(1.0)) and tracker.push(_sample(1.01, 0.001))
    assert not tracker.push(_sample(1.01, 0.002))  # duplicate time
    assert not tracker.push(_sample(0.5, 0.0))  # out of order
    assert not tracker.push(_sample(1.02, 0.5))  # 0.5 m in 10 ms: a glitch
    sample, velocity = tracker.latest()
    assert sample.t_s == 1.01 and velocity[0] == pytest.approx(0.1)
    assert tracker.dropped == 3 and tracker.jumps == 1


def test_a_stream_back_after_a_loss_starts_afresh():
    tracker = PoseTracker(stale_after_s=0.05, lost_after_s=0.5, max_jump_m=0.05)
    assert tracker.push(make_sample(100.0, [0, 0, 0], [1, 0, 0, 0], received_s=1.0))  # occluded
    # real samples 1 m away, then a restarted clock: refused while the baseline is fresh
    assert not tracker.push(make_sample(100.01, [1, 0, 1], [1, 0, 0, 0], received_s=1.01))
    assert not tracker.push(make_sample(0.0, [1, 0, 1], [1, 0, 0, 0], received_s=1.2))
    # once the kept sample is older than lost_after_s, the next one is the new baseline
    assert tracker.push(make_sample(0.3, [1, 0, 1], [1, 0, 0, 0], received_s=1.6))
    assert tracker.push(make_sample(0.31, [1.001, 0, 1], [1, 0, 0, 0], received_s=1.61))
    sample, velocity = tracker.latest()
    assert sample.t_s == 0.31 and velocity[0] == pytest.approx(0.1)
    assert tracker.restarts == 1 and tracker.jumps == 1 and tracker.dropped == 2


def test_tracker_health_ages():
    tracker = PoseTracker(stale_after_s=0.05, lost_after_s=0.5, max_jump_m=0.05)
    assert tracker.health(0.0)[0] == "none"
    tracker.push(make_sample(0.0, [0, 0, 1], [1, 0, 0, 0], received_s=10.0))
    assert tracker.health(10.01)[0] == "ok"
    assert tracker.health(10.1)[0] == "stale"
    assert tracker.health(11.0)[0] == "lost"


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"t_s": math.nan}, "t"),
        ({"position_m": [0, math.inf, 0]}, "position"),
        ({"quaternion": [0, 0, 0, 0]}, "zero"),
        ({"quaternion": [2, 0, 0, 0]}, "unit"),
        ({"velocity_m_s": [0, 0]}, "velocity"),
    ],
)
def test_bad_samples_are_refused_by_name(kwargs, message):
    args = {"t_s": 0.0, "position_m": [0, 0, 1], "quaternion": [1, 0, 0, 0], **kwargs}
    with pytest.raises(PoseError, match=message):
        make_sample(**args)


unit = st.lists(st.floats(-1, 1), min_size=3, max_size=3).filter(lambda v: np.linalg.norm(v) > 0.1)


@given(unit, st.floats(0.1, 3.0), st.floats(0.001, 0.2))
def test_prediction_is_exact_for_constant_rates(axis, rate, ahead):
    """Constant linear and angular velocity: predict() lands on the true later pose."""
    axis = np.array(axis) / np.linalg.norm(axis)
    omega, velocity = rate * axis, np.array([0.3, -0.1, 0.05])

    def true_pose(t: float) -> Pose:
        half = rate * t / 2
        q = np.concatenate([[math.cos(half)], math.sin(half) * axis])
        return Pose(np.array([1.0, 2.0, 3.0]) + velocity * t, q)

    now = true_pose(0.1)
    estimated = angular_velocity(true_pose(0.09).quaternion, now.quaternion, 0.01)
    np.testing.assert_allclose(estimated, omega, atol=1e-9)
    later = predict(now, velocity, estimated, ahead)
    np.testing.assert_allclose(later.position, true_pose(0.1 + ahead).position, atol=1e-12)
    np.testing.assert_allclose(later.rotation, true_pose(0.1 + ahead).rotation, atol=1e-9)


def test_simulated_drone_moves_the_simulated_base():
    """The simulated drone's true attitude and acceleration reach the twin's base each tick."""
    from app.world.drone_sim import DroneSimParams, SimulatedDrone
    from app.world.hold import SimulatedDroneProvider

    felt = []
    drone = SimulatedDrone(DroneSimParams(seed=2))
    provider = SimulatedDroneProvider(drone, lambda q, a, w, w_dot: felt.append((q, a)))
    provider.observe(1.0)
    quaternion, acceleration = felt[-1]
    np.testing.assert_allclose(quaternion, drone.true_state(1.0)[0].quaternion)
    h = 1e-4
    expected = (drone.true_state(1.0 + h)[1] - drone.true_state(1.0 - h)[1]) / (2 * h)
    np.testing.assert_allclose(acceleration, expected, rtol=1e-3, atol=1e-5)
