"""The built-in motion model: laws of the position loop and its limits."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hardware.dynamixel.control_table import OperatingMode
from hardware.shaft_motion import MotionCommand, SimpleServoModel


def run(model: SimpleServoModel, command: MotionCommand, seconds: float, dt: float = 0.005):
    states = []
    for _ in range(round(seconds / dt)):
        states.append(model.step(dt, [command])[0])
    return states


@pytest.mark.slow
@given(st.floats(-3.0, 3.0), st.integers(100, 16000))
def test_position_loop_settles_on_the_goal(goal: float, p_gain: int) -> None:
    model = SimpleServoModel()
    model.reset([0.0])
    command = MotionCommand(True, OperatingMode.POSITION, goal, position_p=p_gain)
    final = run(model, command, 3.0)[-1]
    assert final.position_rad == pytest.approx(goal, abs=1e-3)


@pytest.mark.slow
@given(st.floats(0.5, 3.0), st.floats(0.0, 5.0))
def test_speed_respects_velocity_limit_and_profile(goal: float, profile: float) -> None:
    model = SimpleServoModel()
    model.reset([0.0])
    limit = 7.92
    command = MotionCommand(
        True,
        OperatingMode.POSITION,
        goal,
        profile_velocity_rad_s=profile,
        velocity_limit_rad_s=limit,
    )
    bound = min(limit, profile) if profile > 0 else limit
    assert all(abs(s.velocity_rad_s) <= bound + 1e-9 for s in run(model, command, 1.0))


def test_current_stays_within_the_current_limit() -> None:
    model = SimpleServoModel()
    model.reset([0.0])
    command = MotionCommand(True, OperatingMode.POSITION, 3.0, current_limit_a=0.5)
    assert all(abs(s.current_a) <= 0.5 + 1e-9 for s in run(model, command, 0.5))


def test_higher_p_gain_gets_there_sooner() -> None:
    def error_after(p_gain: int) -> float:
        model = SimpleServoModel()
        model.reset([0.0])
        command = MotionCommand(True, OperatingMode.POSITION, 0.2, position_p=p_gain)
        return abs(0.2 - run(model, command, 0.05)[-1].position_rad)

    assert error_after(1600) < error_after(400)


def test_torque_off_does_not_move() -> None:
    model = SimpleServoModel()
    model.reset([1.0])
    command = MotionCommand(False, OperatingMode.POSITION, -2.0)
    assert all(s.position_rad == 1.0 and s.current_a == 0.0 for s in run(model, command, 0.2))


def test_velocity_mode_tracks_goal_velocity() -> None:
    model = SimpleServoModel()
    model.reset([0.0])
    command = MotionCommand(True, OperatingMode.VELOCITY, 0.0, goal_velocity_rad_s=2.0)
    assert run(model, command, 0.5)[-1].velocity_rad_s == pytest.approx(2.0)


def test_commands_must_match_servos() -> None:
    model = SimpleServoModel()
    model.reset([0.0, 0.0])
    with pytest.raises(ValueError, match="1 commands for 2 servos"):
        model.step(0.01, [MotionCommand(True, OperatingMode.POSITION, 0.0)])
