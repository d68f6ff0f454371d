"""The XM430's velocity-based trajectory profile: Goal Position -> desired motion.

With Profile Velocity and Profile Acceleration both 0 the firmware passes Goal Position
straight to the position loop (a step), which is how the thesis ran its servos. Otherwise
the desired position moves towards the goal with a trapezoidal speed profile. ROBOTIS
replans from the present desired state whenever a goal is written; this online version
does the same every control period: accelerate at most at the profile acceleration, cruise
at most at the profile velocity, and brake so it stops at the goal.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from hardware.shaft_motion import MotionCommand


class ProfileState(NamedTuple):
    """Desired shaft position [rad], velocity [rad/s] and acceleration [rad/s^2]."""

    position_rad: float
    velocity_rad_s: float
    acceleration_rad_s2: float


def step_profile(state: ProfileState, cmd: MotionCommand, dt_s: float) -> ProfileState:
    """The desired motion one control period `dt_s` [s] later under `cmd`."""
    v_max = cmd.profile_velocity_rad_s
    a_max = cmd.profile_acceleration_rad_s2
    goal = cmd.goal_position_rad
    if v_max <= 0 and a_max <= 0:
        return ProfileState(goal, 0.0, 0.0)
    v_max = v_max if v_max > 0 else math.inf
    a_max = a_max if a_max > 0 else math.inf
    error = goal - state.position_rad
    # The fastest speed from which braking at a_max, in steps of dt, still stops on the
    # goal: v (v/(a dt) + 1) dt / 2 = |error| solved for v (the discrete braking distance).
    if math.isfinite(a_max):
        step = a_max * dt_s
        v_stop = step * (math.sqrt(0.25 + 2.0 * abs(error) / (step * dt_s)) - 0.5)
    else:
        v_stop = math.inf
    v_target = math.copysign(min(v_max, v_stop, abs(error) / dt_s), error)
    dv = max(-a_max * dt_s, min(a_max * dt_s, v_target - state.velocity_rad_s))
    velocity = state.velocity_rad_s + dv
    position = state.position_rad + velocity * dt_s
    if abs(goal - position) < 1e-12 and abs(velocity) < 1e-9:
        return ProfileState(goal, 0.0, 0.0)  # arrived: settle exactly on the goal
    return ProfileState(position, velocity, dv / dt_s)
