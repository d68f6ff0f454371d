"""The XM430-W210 model against hand-computed values from its datasheet and e-manual."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from hardware.dynamixel.control_table import RAD_PER_TICK, HardwareErrorFlag, OperatingMode
from hardware.shaft_motion import MotionCommand
from hardware.sim.xm430 import RPM, XM430_W210, Xm430, Xm430Params
from hardware.sim.xm430_profile import ProfileState, step_profile


def position(goal_rad: float, **gains: int) -> MotionCommand:
    return MotionCommand(True, OperatingMode.POSITION, goal_position_rad=goal_rad, **gains)


@pytest.mark.parametrize("speed_fraction", [0.0, 0.25, 0.5, 1.0])
def test_saturated_torque_follows_the_datasheet_torque_speed_line(speed_fraction: float) -> None:
    # 3.0 N m at stall, 0 at the 77 rpm no-load speed, linear between (12 V, PWM 100 %)
    servo = Xm430()
    out = servo.step(position(1.0), 0.0, speed_fraction * 77.0 * RPM)
    assert out.pwm == 885
    assert out.torque_nm == pytest.approx(3.0 * (1.0 - speed_fraction), abs=1e-9)
    assert out.current_a == pytest.approx(2.3 * (1.0 - speed_fraction), abs=1e-9)


def test_stall_torque_scales_with_supply_voltage_and_pwm_limit() -> None:
    high = Xm430(replace(XM430_W210, supply_voltage_v=14.8)).step(position(1.0), 0.0, 0.0)
    assert high.torque_nm == pytest.approx(3.0 * 14.8 / 12.0)
    half = Xm430(replace(XM430_W210, pwm_limit=442)).step(position(1.0), 0.0, 0.0)
    assert half.torque_nm == pytest.approx(3.0 * 442 / 885)


@pytest.mark.parametrize(("p_gain", "error_ticks"), [(800, 10), (128, 7), (3000, -4)])
def test_position_p_gain_is_p_over_128_pwm_per_tick(p_gain: int, error_ticks: int) -> None:
    servo = Xm430()
    out = servo.step(position(error_ticks * RAD_PER_TICK, position_p=p_gain), 0.0, 0.0)
    assert out.pwm == pytest.approx(p_gain / 128 * error_ticks)


def test_integral_gain_is_i_over_65536_per_tick_and_period() -> None:
    servo = Xm430()
    cmd = position(5 * RAD_PER_TICK, position_p=0, position_i=65536)
    outs = [servo.step(cmd, 0.0, 0.0) for _ in range(4)]
    assert [o.pwm for o in outs] == pytest.approx([5.0, 10.0, 15.0, 20.0])


def test_the_firmware_sees_whole_encoder_ticks() -> None:
    # 0.4 tick away from the goal reads as on it: no output at all
    out = Xm430().step(position(0.0), 0.4 * RAD_PER_TICK, 0.0)
    assert out.pwm == 0.0 and out.torque_nm == 0.0


def test_back_emf_brakes_a_shaft_driven_at_zero_pwm() -> None:
    # goal = position: PWM 0, the shorted winding brakes with i = -Ke w / R
    p = XM430_W210
    out = Xm430().step(position(0.0), 0.0, 2.0)
    assert out.current_a == pytest.approx(-p.back_emf_v_s * 2.0 / p.resistance_ohm)
    assert out.torque_nm < 0.0


def test_torque_off_draws_no_current() -> None:
    cmd = replace(position(1.0), torque_enabled=False)
    out = Xm430().step(cmd, 0.0, 3.0)
    assert out.current_a == 0.0 and out.torque_nm == 0.0


def test_overload_trips_when_stalled_too_long_and_reboot_clears_it() -> None:
    params = replace(XM430_W210, overload_time_s=0.05)
    servo = Xm430(params)
    for _ in range(40):
        servo.step(position(1.0), 0.0, 0.0)
    assert servo.hardware_error == 0  # 40 ms saturated: not yet
    for _ in range(20):
        out = servo.step(position(1.0), 0.0, 0.0)
    assert out.hardware_error & HardwareErrorFlag.OVERLOAD
    assert out.torque_nm == 0.0  # the firmware dropped torque
    servo.reboot()
    assert servo.step(position(1.0), 0.0, 0.0).torque_nm > 0.0


def test_temperature_settles_at_ambient_plus_copper_loss_times_thermal_resistance() -> None:
    params = Xm430Params(
        thermal_time_constant_s=0.05, thermal_resistance_k_w=1.0, overload_time_s=math.inf
    )
    idle, stall = Xm430(params), Xm430(params)
    for _ in range(1000):  # 20 time constants
        cool = idle.step(position(0.0), 0.0, 0.0)
        hot = stall.step(position(1.0), 0.0, 0.0)  # 2.3 A
    assert cool.temperature_c == pytest.approx(params.ambient_c)
    rise = 2.3**2 * params.resistance_ohm * params.thermal_resistance_k_w
    assert hot.temperature_c == pytest.approx(params.ambient_c + rise, rel=1e-6)


def test_overheating_trips_at_the_temperature_limit() -> None:
    # 4 K/W at a 27.6 W stall would settle at 135 degC: it trips at 80 and drops torque
    params = Xm430Params(thermal_time_constant_s=0.05, overload_time_s=math.inf)
    servo = Xm430(params)
    hottest = 0.0
    for _ in range(1000):
        out = servo.step(position(1.0), 0.0, 0.0)
        hottest = max(hottest, out.temperature_c)
    assert out.hardware_error & HardwareErrorFlag.OVERHEATING
    assert out.current_a == 0.0
    assert params.temperature_limit_c <= hottest < params.temperature_limit_c + 1.0


@pytest.mark.parametrize(("v_max", "a_max"), [(2.0, 10.0), (1.0, 0.0), (0.0, 5.0)])
def test_profile_respects_velocity_and_acceleration_and_stops_on_the_goal(
    v_max: float, a_max: float
) -> None:
    cmd = replace(position(1.5), profile_velocity_rad_s=v_max, profile_acceleration_rad_s2=a_max)
    state, dt = ProfileState(0.0, 0.0, 0.0), 0.001
    for _ in range(5000):
        new = step_profile(state, cmd, dt)
        if v_max:
            assert abs(new.velocity_rad_s) <= v_max + 1e-9
        if a_max:
            assert abs(new.velocity_rad_s - state.velocity_rad_s) <= a_max * dt + 1e-9
        state = new
    assert state == ProfileState(1.5, 0.0, 0.0)


def test_no_profile_passes_the_goal_through() -> None:
    assert step_profile(ProfileState(0.0, 0.0, 0.0), position(0.7), 0.001).position_rad == 0.7
