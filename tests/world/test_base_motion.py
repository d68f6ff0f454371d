"""The simulated drone's motion as the Delta base feels it, checked against the base's own
trajectory by finite differences (lever arm, mount rotation, turning rates)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.world.drone_sim import DroneSimParams, SimulatedDrone
from app.world.hold import SimulatedDroneProvider, angular_velocity
from app.world.service import base_motion
from kinematics import Pose

# a lively hover, and a base hung 0.3 m off the drone's centre and turned, so every term
# (lever arm, rotation of the rates) is large enough to show a wrong sign or frame
DRONE = DroneSimParams(drift_m=0.05, tilt_deg=8.0, yaw_deg=10.0, bandwidth_hz=1.5, seed=3)
MOUNT = Pose.from_arrays((0.12, -0.05, -0.3), (math.cos(0.4), 0.0, math.sin(0.4), 0.0))
H = 1e-3


def _base_pose(drone: SimulatedDrone, t: float) -> Pose:
    return drone.true_state(t)[0] @ MOUNT


@pytest.mark.parametrize("t", [0.37, 1.9, 4.25, 7.6])
def test_base_motion_matches_the_base_trajectory(t):
    drone = SimulatedDrone(DRONE)
    felt = []
    SimulatedDroneProvider(drone, lambda *args: felt.append(args))._feel(t)
    motion = base_motion(MOUNT, *felt[0])

    poses = [_base_pose(drone, t + k * H) for k in (-2, -1, 0, 1, 2)]
    np.testing.assert_allclose(motion.attitude_wxyz, poses[2].quaternion, atol=1e-12)
    origin = [p.position for p in poses]
    acceleration = (origin[3] - 2 * origin[2] + origin[1]) / H**2
    np.testing.assert_allclose(motion.acceleration_m_s2, acceleration, atol=2e-3)
    # rates of the base in its own frame, from its attitude alone
    rate = [angular_velocity(poses[k].quaternion, poses[k + 1].quaternion, H) for k in range(4)]
    omega = 0.5 * (rate[1] + rate[2])
    np.testing.assert_allclose(motion.angular_velocity_rad_s, omega, atol=1e-5)
    omega_dot = (rate[2] - rate[1]) / H
    np.testing.assert_allclose(motion.angular_acceleration_rad_s2, omega_dot, atol=2e-3)
    assert np.linalg.norm(omega) > 0.01 and np.linalg.norm(omega_dot) > 0.01  # not vacuous


def test_a_still_drone_with_a_level_mount_gives_a_still_base():
    still = SimulatedDrone(DroneSimParams(drift_m=0.0, tilt_deg=0.0, yaw_deg=0.0, gust_m=0.0))
    felt = []
    SimulatedDroneProvider(still, lambda *args: felt.append(args))._feel(2.0)
    motion = base_motion(Pose.from_arrays((0.0, 0.0, -0.08)), *felt[0])
    assert not motion.rotating
    np.testing.assert_allclose(motion.effective_gravity(), [0.0, 0.0, -9.81], atol=1e-9)
