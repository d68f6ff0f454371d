"""DynamixelBus (the ServoBus on dynamixel-sdk) against the emulator: every method, SI units."""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import numpy as np
import pytest

from hardware.bus import PositionGains, ServoBus
from hardware.calibration import JointCalibration
from hardware.dynamixel.control_table import (
    RAD_PER_TICK,
    HardwareErrorFlag,
    OperatingMode,
    Reg,
    acceleration_to_rad_s2,
    velocity_to_rad_s,
)
from hardware.dynamixel.driver import DynamixelBus
from hardware.emulator import ServoEmulator
from hardware.errors import BusError, CommError, NotConnectedError, ServoStatusError
from hardware.shaft_motion import MotionCommand, MotionState, SimpleServoModel
from tests.support.servo_emulator import IDS, fast, make_config
from tests.support.wait import wait_for


class FixedModel:
    """A MotionModel that holds given shaft states, to check conversions exactly."""

    def __init__(self, states: Sequence[MotionState]) -> None:
        self.states = list(states)
        self.commands: list[MotionCommand] = []

    def reset(self, positions_rad: Sequence[float]) -> None:
        pass

    def step(self, dt_s: float, commands: Sequence[MotionCommand]) -> Sequence[MotionState]:
        self.commands = list(commands)
        return self.states


def test_dynamixel_bus_is_a_servo_bus(bus: DynamixelBus) -> None:
    assert isinstance(bus, ServoBus)


@pytest.mark.slow  # absent ids wait out their reply waits (wall time)
def test_scan_reports_model_and_firmware_and_skips_absent(bus: DynamixelBus) -> None:
    found = bus.scan([1, 2, 3, 42])
    assert [(s.servo_id, s.model_number, s.firmware_version) for s in found] == [
        (1, 1030, 46),
        (2, 1030, 46),
        (3, 1030, 46),
    ]


def test_read_state_converts_every_field_to_si() -> None:
    # Joint 1 forward from 2048, joint 2 reversed about 1000, joint 3 forward from 0.
    shafts = [
        MotionState(2148 * RAD_PER_TICK, velocity_to_rad_s(10), 100 * 2.69e-3),
        MotionState(900 * RAD_PER_TICK, velocity_to_rad_s(-20), -50 * 2.69e-3),
        MotionState(-5 * RAD_PER_TICK, 0.0, 0.0),
    ]
    joints = (
        JointCalibration(1, 2048, 1),
        JointCalibration(2, 1000, -1),
        JointCalibration(3, 0, 1),
    )
    with fast(ServoEmulator(IDS, model=FixedModel(shafts))) as emulator:
        bus = DynamixelBus(make_config(emulator.port, joints=joints))
        bus.connect(verify_calibration=False)  # joints 2 and 3 reach past the seam: unchecked
        try:
            state = bus.read_state()
        finally:
            bus.disconnect()
    np.testing.assert_allclose(state.position_rad, np.array([100, 100, -5]) * RAD_PER_TICK)
    np.testing.assert_allclose(state.velocity_rad_s, velocity_to_rad_s(np.array([10, 20, 0])))
    np.testing.assert_allclose(state.current_a, np.array([0.269, 0.1345, 0.0]))
    np.testing.assert_allclose(state.voltage_v, [12.0, 12.0, 12.0])
    np.testing.assert_allclose(state.temperature_c, [30, 30, 30])
    assert state.moving.tolist() == [False, True, False]  # |-20| > threshold 10
    assert state.hardware_errors == ((), (), ()) and not state.faulted


def test_write_goal_goes_out_in_calibrated_ticks(emulator: ServoEmulator) -> None:
    joints = (
        JointCalibration(1, 2048, 1),
        JointCalibration(2, 2048, -1),
        JointCalibration(3, 1000, 1, -0.1, 0.1),
    )
    bus = DynamixelBus(make_config(emulator.port, joints=joints))
    bus.connect()
    try:
        bus.write_goal([math.pi / 4, math.pi / 4, 1.0])  # joint 3 clamped to 0.1 rad
        bus.scan([1])  # sync write has no answer: a round trip after it orders the check
    finally:
        bus.disconnect()
    goals = [emulator.servo(i).table.get(Reg.GOAL_POSITION) for i in IDS]
    assert goals == [2048 + 512, 2048 - 512, 1000 + round(0.1 / RAD_PER_TICK)]


def test_write_goal_refuses_bad_input(bus: DynamixelBus) -> None:
    with pytest.raises(ValueError, match="non-finite"):
        bus.write_goal([0.0, math.nan, 0.0])
    with pytest.raises(ValueError, match="2 goals for 3 joints"):
        bus.write_goal([0.0, 0.0])


def test_torque_on_holds_the_present_pose_and_moves_to_goals(bus, emulator) -> None:
    emulator.place({1: 2100, 2: 2000, 3: 2048})
    emulator.servo(1).table.set(Reg.GOAL_POSITION, 4000)  # a stale goal must not be used
    bus.torque(True)
    assert [emulator.servo(i).table.get(Reg.TORQUE_ENABLE) for i in IDS] == [1, 1, 1]
    assert emulator.servo(1).table.get(Reg.GOAL_POSITION) == 2100
    goal = [0.2, -0.1, 0.0]

    def arrived():  # the simple model settles in ~0.1 s; poll, don't time
        state = bus.read_state()
        bus.write_goal(goal)
        return state if np.allclose(state.position_rad, goal, atol=2 * RAD_PER_TICK) else None

    state = wait_for(arrived, f"the joints at {goal} rad", 10.0, poll_s=0.01)
    np.testing.assert_allclose(state.position_rad, goal, atol=2 * RAD_PER_TICK)
    bus.torque(False)
    assert [emulator.servo(i).table.get(Reg.TORQUE_ENABLE) for i in IDS] == [0, 0, 0]


def test_operating_mode_needs_torque_off(bus: DynamixelBus, emulator: ServoEmulator) -> None:
    bus.set_operating_mode(OperatingMode.CURRENT_BASED_POSITION)
    assert [emulator.servo(i).table.get(Reg.OPERATING_MODE) for i in IDS] == [5, 5, 5]
    bus.torque(True)
    with pytest.raises(ServoStatusError, match="servo 1 failed: access error") as info:
        bus.set_operating_mode(OperatingMode.POSITION)
    assert info.value.ids == (1,) and info.value.instruction == "write OPERATING_MODE"


def test_profile_in_si_units(bus: DynamixelBus, emulator: ServoEmulator) -> None:
    bus.set_profile(velocity_rad_s=velocity_to_rad_s(50), acceleration_rad_s2=200.0)
    for i in IDS:
        table = emulator.servo(i).table
        assert table.get(Reg.PROFILE_VELOCITY) == 50
        units = table.get(Reg.PROFILE_ACCELERATION)
        assert abs(acceleration_to_rad_s2(units) - 200.0) <= acceleration_to_rad_s2(0.5)
    with pytest.raises(ValueError):
        bus.set_profile(-1.0, 0.0)


def test_a_small_profile_is_written_as_the_smallest_limit_never_as_unlimited(
    bus: DynamixelBus, emulator: ServoEmulator, caplog: pytest.LogCaptureFixture
) -> None:
    # 0.01 rad/s is 0.42 of a 0.229 rpm unit and 0.1 rad/s^2 0.27 of a 214.577 rev/min^2
    # unit: rounded they would be 0, which the XM430 reads as no limit at all.
    bus.set_profile(velocity_rad_s=0.01, acceleration_rad_s2=0.1)
    for i in IDS:
        table = emulator.servo(i).table
        assert (table.get(Reg.PROFILE_VELOCITY), table.get(Reg.PROFILE_ACCELERATION)) == (1, 1)
    said = [r.getMessage() for r in caplog.records if "writing 1 unit" in r.getMessage()]
    assert len(said) == 2 and "velocity_rad_s 0.01" in said[0]
    caplog.clear()
    bus.set_profile(velocity_rad_s=0.0, acceleration_rad_s2=0.0)  # 0 asked: unlimited
    for i in IDS:
        table = emulator.servo(i).table
        assert (table.get(Reg.PROFILE_VELOCITY), table.get(Reg.PROFILE_ACCELERATION)) == (0, 0)
    assert not [r for r in caplog.records if "writing 1 unit" in r.getMessage()]


def test_gains(bus: DynamixelBus, emulator: ServoEmulator) -> None:
    bus.set_gains(PositionGains(p=900, i=10, d=20, feedforward_1st=30, feedforward_2nd=40))
    items = (
        Reg.POSITION_P_GAIN,
        Reg.POSITION_I_GAIN,
        Reg.POSITION_D_GAIN,
        Reg.FEEDFORWARD_1ST_GAIN,
        Reg.FEEDFORWARD_2ND_GAIN,
    )
    for i in IDS:
        assert [emulator.servo(i).table.get(r) for r in items] == [900, 10, 20, 30, 40]
    with pytest.raises(ServoStatusError, match="data range"):
        bus.set_gains(PositionGains(p=20000))
    # one set per joint, in joint order: each servo's registers hold its own
    each = [PositionGains(p=1000 + k, i=k, d=2 * k, feedforward_1st=3 * k) for k in range(len(IDS))]
    bus.set_gains(each)
    for k, i in enumerate(IDS):
        assert [emulator.servo(i).table.get(r) for r in items] == [1000 + k, k, 2 * k, 3 * k, 0]
    assert bus.read_gains() == each  # read back from the servos' registers
    with pytest.raises(ValueError, match="joints"):
        bus.set_gains(each[:-1])


def test_hardware_error_surfaces_by_name_and_reboot_clears_it(bus, emulator) -> None:
    emulator.raise_hardware_error(2, HardwareErrorFlag.OVERLOAD | HardwareErrorFlag.OVERHEATING)
    state = bus.read_state()
    assert state.faulted and state.hardware_errors[1] == ("overheating", "overload")
    assert state.hardware_errors[0] == state.hardware_errors[2] == ()
    with pytest.raises(BusError, match="servo 2: overheating, overload"):
        bus.torque(True)
    bus.reboot([2])
    assert not bus.read_state().faulted
    assert emulator.servo(2).reboots == 1


def test_read_ticks_and_registers_for_homing(bus: DynamixelBus, emulator) -> None:
    emulator.place({1: 10, 2: 20, 3: 4000})
    assert bus.read_ticks() == {1: 10, 2: 20, 3: 4000}
    bus.write_register(2, Reg.RETURN_DELAY_TIME, 5)
    assert bus.read_register(2, Reg.RETURN_DELAY_TIME) == 5


def test_position_limits_follow_the_calibration(emulator: ServoEmulator) -> None:
    joints = tuple(JointCalibration(i, 2048, 1, -1.0, 0.5) for i in IDS)
    bus = DynamixelBus(make_config(emulator.port, joints=joints))
    bus.connect()
    try:
        bus.write_position_limits()
    finally:
        bus.disconnect()
    table = emulator.servo(1).table
    low, high = joints[0].tick_limits()
    assert (table.get(Reg.MIN_POSITION_LIMIT), table.get(Reg.MAX_POSITION_LIMIT)) == (low, high)


@pytest.mark.slow
def test_connect_names_missing_servos(emulator: ServoEmulator) -> None:
    joints = tuple(JointCalibration(i) for i in (1, 2, 5))
    config = make_config(emulator.port, joints=joints, max_tries=1, connect_timeout_s=0.0)
    bus = DynamixelBus(config)
    with pytest.raises(CommError, match="ping on servo 5 failed: servo not found"):
        bus.connect()


@pytest.mark.slow  # the emulator answers late on purpose (wall time)
def test_connect_waits_for_a_servo_slow_to_answer(emulator: ServoEmulator) -> None:
    # Servo 2 misses its first four pings (one round of three tries, and one more), as a
    # servo still booting or an emulator not yet scheduled on a loaded machine does.
    emulator.inject(2, drop_replies=4)
    bus = DynamixelBus(make_config(emulator.port, connect_timeout_s=10.0))  # 4 waits of 1 s
    bus.connect()
    try:
        assert bus.read_register(2, Reg.ID) == 2
        assert bus.stats.failed_tries >= 4
    finally:
        bus.disconnect()


class SlowFirstStep(SimpleServoModel):
    """The emulator's model, with a first step as slow as the MuJoCo twin's catch-up after
    idling (up to 0.25 s of physics) on a loaded machine."""

    def __init__(self, first_step_s: float) -> None:
        super().__init__()
        self.first_step_s = first_step_s

    def step(self, dt_s: float, commands: Sequence[MotionCommand]) -> Sequence[MotionState]:
        if self.first_step_s:
            time.sleep(self.first_step_s)
            self.first_step_s = 0.0
        return super().step(dt_s, commands)


def test_a_fresh_emulator_slow_to_answer_connects_and_reads_true_values() -> None:
    # Its first answer comes after all three tries of the first ping have timed out; the
    # answers it then owes arrive while other servos are asked, and are discarded.
    with fast(ServoEmulator(IDS, model=SlowFirstStep(0.2))) as emulator:
        emulator.place({1: 1000, 2: 2000, 3: 3000})
        bus = DynamixelBus(make_config(emulator.port))
        bus.connect()
        try:
            assert [info.model_number for info in bus.scan()] == [1030] * 3
            assert [bus.read_register(i, Reg.GOAL_POSITION) for i in IDS] == [1000, 2000, 3000]
            assert bus.read_ticks() == {1: 1000, 2: 2000, 3: 3000}
        finally:
            bus.disconnect()


def test_connect_refuses_another_model(emulator: ServoEmulator) -> None:
    bus = DynamixelBus(make_config(emulator.port, expected_model=1020))
    with pytest.raises(BusError, match="model 1030, 1030, 1030, expected 1020"):
        bus.connect()


def test_connect_to_a_missing_port_is_a_comm_error() -> None:
    bus = DynamixelBus(make_config("/dev/does-not-exist"))
    with pytest.raises(CommError, match="cannot open /dev/does-not-exist"):
        bus.connect()


def test_calls_after_disconnect_raise(bus: DynamixelBus) -> None:
    bus.disconnect()
    with pytest.raises(NotConnectedError):
        bus.read_state()
    with pytest.raises(NotConnectedError):
        bus.write_goal([0.0, 0.0, 0.0])
    with pytest.raises(NotConnectedError):
        bus.torque(False)


def test_stats_count_transactions(bus: DynamixelBus) -> None:
    before = bus.stats.transactions
    bus.read_state()
    bus.write_goal([0.0, 0.0, 0.0])
    stats = bus.stats
    assert stats.transactions == before + 2
    assert (stats.failed_tries, stats.retries, stats.failures) == (0, 0, 0)


@pytest.mark.slow  # absent ids wait out their reply waits (wall time)
def test_bad_ids_are_named(bus: DynamixelBus) -> None:
    with pytest.raises(CommError, match="read ID on servo 42 failed after 3 tries"):
        bus.read_register(42, Reg.ID)
    with pytest.raises(ValueError, match="distinct"):
        make_config("/dev/null", joints=(JointCalibration(1), JointCalibration(1)))


def test_baud_rates_beyond_the_sdk_list(emulator: ServoEmulator) -> None:
    bus = DynamixelBus(make_config(emulator.port, baudrate=4_500_000))
    bus.connect()
    try:
        assert bus.link.port.getBaudRate() == 4_500_000
        assert len(bus.scan()) == 3
    finally:
        bus.disconnect()
    with pytest.raises(CommError, match="refused baud rate 12345"):
        DynamixelBus(make_config(emulator.port, baudrate=12345)).connect()


def test_present_pwm_is_read_as_a_signed_fraction_of_full_duty(bus, emulator) -> None:
    """Present PWM (124, signed, 885 = 100 %) reaches the state in the joint's direction."""
    units = {1: -442, 2: 885, 3: 0}
    for servo in emulator.servos:
        servo.table.set(Reg.PRESENT_PWM, units[servo.servo_id])
    sign = np.array([cal.direction for cal in bus.config.joints], dtype=float)
    expected = sign * np.array([units[i] for i in IDS]) / 885
    wait_for(lambda: np.allclose(bus.read_state().pwm, expected), 5.0, "the PWM written")
