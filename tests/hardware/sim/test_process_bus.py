"""ProcessSimBus: the twin in a child process behind the same ServoBus interface."""

from __future__ import annotations

import pickle
import time
from collections.abc import Iterator

import numpy as np
import pytest

from hardware.bus import PositionGains, ServoBus
from hardware.dynamixel.control_table import RAD_PER_TICK, OperatingMode
from hardware.errors import BusError, CommError, HardwareError, NotConnectedError, ServoStatusError
from hardware.sim import BaseMotion, ProcessSimBus, SimBusConfig
from kinematics import THESIS_DELTA
from tests.support.wait import wait_for


@pytest.fixture(scope="module")
def bus() -> Iterator[ProcessSimBus]:
    sim = ProcessSimBus(SimBusConfig())
    sim.connect()
    yield sim
    sim.disconnect()


def test_bus_errors_survive_pickling_with_their_fields() -> None:
    errors = [
        BusError((1, 2), "read", "because", tries=3),
        CommError((3,), "ping", "timeout"),
        ServoStatusError((2,), "write GOAL", "data range", error_number=4, tries=2),
        HardwareError((1,), "write TORQUE_ENABLE", {1: ("overload",)}),
    ]
    for error in errors:
        copy = pickle.loads(pickle.dumps(error))
        assert type(copy) is type(error) and str(copy) == str(error)
        assert copy.__dict__ == error.__dict__


@pytest.mark.slow
def test_the_relaxed_arm_falls_then_holds_a_goal(bus: ProcessSimBus) -> None:
    assert isinstance(bus, ServoBus)
    assert [info.servo_id for info in bus.scan()] == [1, 2, 3]
    # powered up with torque off: gravity swings the upper links down (theta grows)
    wait_for(lambda: bus.read_state().position_rad.min() > 1.0, "the arm to fall")
    assert bus.read_state().torque_enabled == (False, False, False)
    bus.torque(True)
    wait_for(lambda: bus.read_state().torque_enabled == (True,) * 3, "torque on in the frame")
    bus.write_goal([0.3, 0.4, 0.5])

    def holding() -> bool:
        state = bus.read_state()
        near = np.abs(state.position_rad - [0.3, 0.4, 0.5]).max() < 8 * RAD_PER_TICK
        return near and bool(np.all(state.current_a < 0))  # lifting against gravity

    wait_for(holding, "the goal to be reached and held")
    state = bus.read_state()
    ticks = state.position_rad / RAD_PER_TICK
    assert ticks == pytest.approx(np.round(ticks), abs=1e-9)  # whole ticks, as the servo
    assert list(state.voltage_v) == [12.0] * 3 and not state.faulted
    assert abs(state.stamp_s - time.monotonic()) < 1.0  # one clock for both processes


def test_the_external_measurement_agrees_with_fk_of_the_same_read(bus: ProcessSimBus) -> None:
    bus.torque(True)
    bus.write_goal([0.45, 0.45, 0.45])
    wait_for(lambda: not bus.read_state().moving.any(), "the arm to settle")
    state = bus.read_state()
    platform = bus.measure_platform(at_last_read=True)
    # encoder resolution (0.088 deg on ~0.16 m links) bounds the disagreement
    assert np.linalg.norm(THESIS_DELTA.fk(state.position_rad).points - platform) < 1e-3


def test_errors_raised_in_the_child_reach_the_caller(bus: ProcessSimBus) -> None:
    bus.torque(True)
    with pytest.raises(BusError, match="EEPROM item"):
        bus.set_operating_mode(OperatingMode.POSITION)
    with pytest.raises(ValueError, match="non-finite"):
        bus.write_goal([float("nan"), 0.0, 0.0])
    with pytest.raises(ValueError, match="profile"):
        bus.set_profile(-1.0, 0.0)
    bus.set_gains(PositionGains(p=900))  # accepted, and the bus still answers
    bus.set_base_motion(BaseMotion())
    assert bus.read_state().position_rad.shape == (3,)


@pytest.mark.slow
def test_after_disconnect_the_child_is_gone_and_calls_fail() -> None:
    sim = ProcessSimBus(SimBusConfig())
    with pytest.raises(NotConnectedError):
        sim.read_state()
    with pytest.raises(NotConnectedError):
        sim.measure_platform()
    sim.connect()
    process = sim._process
    sim.disconnect()
    assert process is not None and not process.is_alive()
    with pytest.raises(NotConnectedError):
        sim.read_state()
    with pytest.raises(NotConnectedError):
        sim.torque(True)


@pytest.mark.slow
def test_a_dead_simulator_is_a_bus_error_not_a_frozen_robot() -> None:
    sim = ProcessSimBus(SimBusConfig())
    sim.connect()
    try:
        sim.read_state()
        assert sim._process is not None
        sim._process.kill()

        def read_fails() -> bool:
            try:
                sim.read_state()
            except BusError as exc:
                return "stopped stepping" in str(exc)
            return False

        wait_for(read_fails, "reads of a dead simulator to fail")
        with pytest.raises(BusError):
            sim.torque(True)
    finally:
        sim.disconnect()


def test_a_paused_simulator_hands_out_the_same_state_with_the_same_simulated_time(
    bus: ProcessSimBus,
) -> None:
    first = bus.read_state().sim_time_s
    later = wait_for(lambda: (t := bus.read_state().sim_time_s) > first and t, "time to run")
    bus.pause(True)
    try:
        paused = bus.read_state()
        again = wait_for(
            lambda: (s := bus.read_state()).stamp_s == paused.stamp_s and s, "a repeated frame"
        )
    finally:
        bus.pause(False)
    assert paused.sim_time_s >= later  # the simulated time of the state it returns
    assert again.sim_time_s == paused.sim_time_s  # the same state, and it says so
    np.testing.assert_array_equal(again.position_rad, paused.position_rad)
    wait_for(lambda: bus.read_state().sim_time_s > paused.sim_time_s, "time to run again")
