"""The twin as the emulator's motion model, driven over the real SDK and driver."""

from __future__ import annotations

import pytest

from hardware.bus import PositionGains
from hardware.calibration import JointCalibration
from hardware.dynamixel.control_table import RAD_PER_TICK
from hardware.dynamixel.driver import DynamixelBus, DynamixelConfig
from hardware.emulator import ServoEmulator
from hardware.sim.twin_shaft_motion import TwinMotionModel
from tests.support.servo_emulator import fast
from tests.support.wait import wait_for


def test_reset_places_the_arm_at_the_shaft_angles() -> None:
    model = TwinMotionModel()
    shafts = [2048 * RAD_PER_TICK + a for a in (0.3, 0.4, 0.5)]
    model.reset(shafts)
    assert list(model.twin.shaft_rad) == pytest.approx(shafts, abs=1e-9)
    states = model.step(0.0, model.twin.commands)
    assert [s.position_rad for s in states] == pytest.approx(shafts, abs=1e-9)


@pytest.mark.slow
def test_goals_and_gains_written_over_the_sdk_drive_the_twin() -> None:
    model = TwinMotionModel()
    joints = tuple(JointCalibration(i) for i in (1, 2, 3))
    with fast(ServoEmulator((1, 2, 3), model=model)) as emulator:
        bus = DynamixelBus(DynamixelConfig(joints=joints, port=emulator.port))
        bus.connect()
        try:
            bus.set_gains(PositionGains(p=1200))
            bus.torque(True)
            bus.write_goal([0.45, 0.45, 0.45])

            def later() -> bool:
                bus.read_state()  # the bus's requests are what step the twin
                return model.twin.time_s >= 0.6

            wait_for(later, "0.6 s of simulated time", 10.0, poll_s=0.01)
            state = bus.read_state()
        finally:
            bus.disconnect()
    assert all(cmd.position_p == 1200 for cmd in model.twin.commands)
    assert state.position_rad == pytest.approx([0.45] * 3, abs=0.01)
    assert model.twin.joints_rad == pytest.approx([0.45] * 3, abs=0.01)


def test_reboot_clears_a_servo_models_latched_error() -> None:
    model = TwinMotionModel()
    model.twin.servos[2].hardware_error = 0x20
    model.reboot(2)
    assert model.twin.servos[2].hardware_error == 0


def test_the_twins_heat_and_errors_reach_the_control_table_and_reboot_clears_both() -> None:
    """A latched overload in the twin's servo shows in Hardware Error Status over the SDK,
    with the twin's winding temperature, and a Reboot over the bus clears it in both."""
    model = TwinMotionModel()
    joints = tuple(JointCalibration(i) for i in (1, 2, 3))
    with fast(ServoEmulator((1, 2, 3), model=model)) as emulator:
        bus = DynamixelBus(DynamixelConfig(joints=joints, port=emulator.port))
        bus.connect()
        try:
            model.twin.servos[1].hardware_error = 0x20  # overload, latched in servo 2's model

            def latched():
                state = bus.read_state()
                return state if state.hardware_errors[1] else None

            overload = "servo 2's overload in Hardware Error Status"
            state = wait_for(latched, overload, 10.0, poll_s=0.01)
            assert not state.hardware_errors[0]
            expected = [round(out.temperature_c) for out in model.outputs]
            assert list(state.temperature_c) == pytest.approx(expected, abs=1)
            bus.reboot([2])
            state = bus.read_state()
            state = bus.read_state()
        finally:
            bus.disconnect()
    assert model.twin.servos[1].hardware_error == 0 and not state.hardware_errors[1]
