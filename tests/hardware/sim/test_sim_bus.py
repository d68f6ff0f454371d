"""SimBus: the twin behind the ServoBus interface, with the Dynamixel driver's units."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest

from hardware.bus import PositionGains, ServoBus
from hardware.dynamixel.control_table import (
    AMPERE_PER_CURRENT_UNIT,
    RAD_PER_TICK,
    HardwareErrorFlag,
    OperatingMode,
)
from hardware.errors import BusError, HardwareError, NotConnectedError
from hardware.sim.sim_bus import SimBus, SimBusConfig
from tests.support.wait import wait_for


@pytest.fixture
def bus() -> Iterator[SimBus]:
    sim = SimBus(SimBusConfig(realtime=False, torque_on_at_start=True))
    sim.connect()
    yield sim
    sim.disconnect()


def test_it_is_a_servo_bus_and_refuses_work_before_connect() -> None:
    sim = SimBus(SimBusConfig(realtime=False))
    assert isinstance(sim, ServoBus)
    with pytest.raises(NotConnectedError):
        sim.read_state()


def test_a_goal_is_reached_and_reads_back_in_whole_ticks(bus: SimBus) -> None:
    bus.write_goal([0.3, 0.4, 0.5])
    bus.advance(1.0)
    state = bus.read_state()
    # P only: a few ticks of droop under gravity (about 0.02 N m per tick at P = 800)
    assert state.position_rad == pytest.approx([0.3, 0.4, 0.5], abs=8 * RAD_PER_TICK)
    ticks = state.position_rad / RAD_PER_TICK  # zero offset 2048, direction +1
    assert ticks == pytest.approx(np.round(ticks), abs=1e-9)
    units = state.current_a / AMPERE_PER_CURRENT_UNIT
    assert units == pytest.approx(np.round(units), abs=1e-6)
    assert np.all(state.current_a < 0)  # holding the arm up takes negative torque
    assert list(state.voltage_v) == [12.0] * 3 and not state.faulted


def test_goals_are_clamped_to_the_calibrated_limits(bus: SimBus) -> None:
    bus.write_goal([3.0, 0.4, 0.4])
    limit = bus.joints[0].max_angle_rad
    expected = bus.joints[0].to_ticks(limit) * RAD_PER_TICK
    assert bus.commands[0].goal_position_rad == pytest.approx(expected)
    with pytest.raises(ValueError):
        bus.write_goal([float("nan"), 0.0, 0.0])


def test_gains_and_profile_reach_the_servo_models(bus: SimBus) -> None:
    bus.set_gains(PositionGains(p=1600, i=100, d=50))
    bus.set_profile(2.0, 20.0)
    cmd = bus.commands[2]
    assert (cmd.position_p, cmd.position_i, cmd.position_d) == (1600, 100, 50)
    assert cmd.profile_velocity_rad_s == pytest.approx(2.0, abs=0.024)  # 0.229 rpm units
    assert bus.twin.commands[2] is cmd
    bus.set_gains([PositionGains(p=700 + k, feedforward_2nd=k) for k in range(3)])
    assert [(c.position_p, c.feedforward_2nd) for c in bus.commands] == [
        (700, 0),
        (701, 1),
        (702, 2),
    ]
    assert bus.read_gains() == [PositionGains(p=700 + k, feedforward_2nd=k) for k in range(3)]
    with pytest.raises(ValueError, match="joints"):
        bus.set_gains([PositionGains()] * 4)


def test_a_small_profile_stays_limited_in_the_twin(bus: SimBus) -> None:
    bus.set_profile(0.01, 0.1)  # both round to 0 units: must become 1 unit, not unlimited
    cmd = bus.commands[0]
    assert cmd.profile_velocity_rad_s == pytest.approx(0.229 * 2 * math.pi / 60)
    assert cmd.profile_acceleration_rad_s2 == pytest.approx(214.577 * 2 * math.pi / 3600)
    bus.set_profile(0.0, 0.0)
    cmd = bus.commands[0]
    assert (cmd.profile_velocity_rad_s, cmd.profile_acceleration_rad_s2) == (0.0, 0.0)


def test_operating_mode_is_refused_while_torque_is_on(bus: SimBus) -> None:
    with pytest.raises(BusError):
        bus.set_operating_mode(OperatingMode.VELOCITY)
    bus.torque(False)
    bus.set_operating_mode(OperatingMode.VELOCITY)
    assert bus.commands[0].mode == OperatingMode.VELOCITY


def test_a_latched_hardware_error_is_named_refuses_torque_and_reboot_clears_it(bus: SimBus) -> None:
    bus.twin.servos[1].hardware_error = int(HardwareErrorFlag.OVERLOAD)
    bus.advance(0.01)
    state = bus.read_state()
    assert state.hardware_errors == ((), ("overload",), ())
    with pytest.raises(HardwareError) as err:
        bus.torque(True)
    assert err.value.ids == (2,)
    bus.reboot([2])
    assert not bus.read_state().faulted
    assert not bus.commands[1].torque_enabled  # back from a reboot with torque off
    bus.torque(True)


def test_torque_off_at_power_up_lets_the_arm_fall() -> None:
    sim = SimBus(SimBusConfig(realtime=False))
    sim.connect()
    start = sim.read_state().position_rad
    sim.advance(0.3)
    assert np.all(sim.read_state().position_rad > start + 0.1)  # + is down
    sim.disconnect()


def test_external_measurement_has_the_marker_offset_and_the_noise_asked_for() -> None:
    offset = (0.01, -0.02, 0.005)
    sim = SimBus(SimBusConfig(realtime=False, torque_on_at_start=True, marker_offset_m=offset))
    sim.connect()
    assert sim.measure_platform() == pytest.approx(sim.twin.platform_m + offset, abs=1e-15)
    noisy = SimBus(SimBusConfig(realtime=False, torque_on_at_start=True, noise_std_m=1e-3))
    noisy.connect()
    samples = np.array([noisy.measure_platform() for _ in range(4000)]) - noisy.twin.platform_m
    assert np.abs(samples.mean(axis=0)).max() < 1e-4
    assert samples.std(axis=0) == pytest.approx([1e-3] * 3, rel=0.1)


def test_realtime_bus_moves_simulated_time_by_itself() -> None:
    sim = SimBus(SimBusConfig(realtime=True, torque_on_at_start=True))
    sim.connect()
    try:
        wait_for(
            lambda: sim.twin.time_s >= 0.05,
            "simulated time to reach 0.05 s by itself",
            10.0,
            poll_s=0.01,
            seen=lambda: f"{sim.twin.time_s} s",
        )
        with pytest.raises(RuntimeError):
            sim.advance(0.1)  # the thread owns the clock
    finally:
        sim.disconnect()


def test_each_state_carries_the_simulated_time_it_was_taken_at(bus: SimBus) -> None:
    before = bus.read_state()
    assert bus.read_state().sim_time_s == before.sim_time_s  # no step: the same state again
    bus.advance(0.05)
    after = bus.read_state()
    assert after.sim_time_s == pytest.approx(before.sim_time_s + 0.05)
    assert after.sim_time_s == bus.twin.time_s


def test_an_overload_shuts_the_servo_down_and_its_torque_reads_off(bus: SimBus) -> None:
    bus.torque(True)
    assert bus.read_state().torque_enabled == (True, True, True)
    bus.twin.servos[0].hardware_error = int(HardwareErrorFlag.OVERLOAD)
    bus.advance(0.01)
    state = bus.read_state()
    # the XM430's Shutdown (63) turns Torque Enable off for an overload, as on the servo
    assert state.hardware_errors == (("overload",), (), ())
    assert state.torque_enabled == (False, True, True)
    assert not bus.commands[0].torque_enabled
    bus.reboot([1])
    assert bus.read_state().torque_enabled == (False, True, True)


def test_the_pwm_read_drives_the_current_read_through_the_winding(bus: SimBus) -> None:
    """At rest, holding the arm up, the motor's equation V * pwm = R * i (no back-EMF)
    relates the two readings: Present PWM (a fraction of full duty) and Present Current,
    each rounded to its register's unit."""
    bus.write_goal([0.4, 0.4, 0.4])
    bus.advance(1.0)
    state = bus.read_state()
    params = bus.twin.servos[0].params
    assert np.all(state.pwm < 0) and np.all(np.abs(state.pwm) <= 1.0)  # the arm hangs
    volts = params.supply_voltage_v * state.pwm
    amperes = volts / params.resistance_ohm
    assert state.current_a == pytest.approx(amperes, abs=2 * AMPERE_PER_CURRENT_UNIT)
    assert set(state.readings()) == {
        "velocity_rad_s",
        "current_a",
        "voltage_v",
        "temperature_c",
        "pwm",
    }
