"""The driver and the servos' reach (hardware/dynamixel/driver.py, hardware/seam.py) on the
emulated bus through the real dynamixel-sdk: connect refuses a calibration across the
encoder's seam, position limits are never clipped, and a goal the servo would refuse
raises naming it. The issue's joint: raw 4000 at theta = 0, direction +1, limits
-0.6 .. 1.4 rad = 3609 .. 4913 ticks; 1.0 rad is 4000 + round(1.0 * 4096 / 2 pi) = 4652."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from hardware.calibration import JointCalibration
from hardware.dynamixel.control_table import Reg
from hardware.dynamixel.driver import DynamixelBus
from hardware.dynamixel.protocol import StatusError
from hardware.emulator import ServoEmulator
from hardware.errors import NotConnectedError, ServoStatusError
from hardware.seam import SeamError
from tests.support.servo_emulator import IDS, make_config

ACROSS = JointCalibration(2, 4000, 1, -0.6, 1.4)
JOINTS = (JointCalibration(1, 2048, 1, -0.6, 1.4), ACROSS, JointCalibration(3, 2048, 1, -0.6, 1.4))


@pytest.fixture
def unchecked(emulator: ServoEmulator) -> Iterator[DynamixelBus]:
    """A bus with the issue's joint 2, connected without the calibration check (as before)."""
    emulator.place({1: 2048, 2: 4000, 3: 2048})
    dxl = DynamixelBus(make_config(emulator.port, joints=JOINTS))
    dxl.connect(verify_calibration=False)
    try:
        yield dxl
    finally:
        dxl.disconnect()


def limits(emulator: ServoEmulator) -> list[tuple[int, int]]:
    return [
        (
            emulator.servo(i).table.get(Reg.MIN_POSITION_LIMIT),
            emulator.servo(i).table.get(Reg.MAX_POSITION_LIMIT),
        )
        for i in IDS
    ]


def test_connect_refuses_a_calibration_across_the_seam(emulator: ServoEmulator) -> None:
    bus = DynamixelBus(make_config(emulator.port, joints=JOINTS))
    with pytest.raises(SeamError, match=r"servo 2 \(joint 2\).* 3609 \.\. 4913 ticks.*seam"):
        bus.connect()
    with pytest.raises(NotConnectedError):  # the port was closed again
        bus.read_state()


def test_write_position_limits_never_clips(unchecked: DynamixelBus, emulator) -> None:
    before = limits(emulator)
    with pytest.raises(SeamError, match=r"servo 2 \(joint 2\).* 3609 \.\. 4913 ticks"):
        unchecked.write_position_limits()
    assert limits(emulator) == before == [(0, 4095)] * 3  # nothing written, on any servo


def test_a_goal_the_servo_refuses_raises_naming_it(unchecked: DynamixelBus, emulator) -> None:
    # The servo itself refuses 4652 (data limit error) and keeps its goal ...
    with pytest.raises(ServoStatusError, match="data limit") as info:
        unchecked.write_register(2, Reg.GOAL_POSITION, 4652)
    assert info.value.ids == (2,) and info.value.error_number == StatusError.DATA_LIMIT
    unchecked.torque(True)
    # ... and a sync write gets no status: the driver says it, before sending anything.
    with pytest.raises(
        ServoStatusError, match="servo 2: goal 4652 ticks outside its limits 0 .. 4095"
    ) as info:
        unchecked.write_goal([0.0, 1.0, 0.0])
    assert info.value.ids == (2,) and info.value.error_number == StatusError.DATA_LIMIT
    unchecked.read_state()  # a round trip: the emulator has handled all that was sent
    assert emulator.servo(2).table.get(Reg.GOAL_POSITION) == 4000  # held where it was
    with pytest.raises(ServoStatusError, match="servo 2: goal 4196 ticks"):
        unchecked.write_goal([0.1, 0.3, 0.1])  # 0.3 rad = 196 ticks: 4196, past 4095
    unchecked.write_goal([0.1, -0.5, 0.1])  # -0.5 rad = -326 ticks: 3674 goes through
    unchecked.read_state()
    assert emulator.servo(2).table.get(Reg.GOAL_POSITION) == 3674


def test_goal_checks_follow_limits_written_later(bus: DynamixelBus, emulator) -> None:
    bus.write_register(1, Reg.MAX_POSITION_LIMIT, 2500)  # the driver re-reads the setup
    bus.torque(True)
    bus.write_goal([0.2, 0.0, 0.0])  # 0.2 rad = 130 ticks: 2178
    bus.read_state()  # a round trip: the emulator has handled the sync write
    assert emulator.servo(1).table.get(Reg.GOAL_POSITION) == 2178
    with pytest.raises(
        ServoStatusError, match="servo 1: goal 2700 ticks outside its limits 0 .. 2500"
    ):
        bus.write_goal([1.0, 0.0, 0.0])  # 1.0 rad = 652 ticks: 2700
    bus.read_state()
    assert emulator.servo(1).table.get(Reg.GOAL_POSITION) == 2178


def test_torque_on_past_the_limits_is_refused_not_a_jump(bus: DynamixelBus, emulator) -> None:
    # A relaxed link resting past Max Position Limit: holding it there is a goal the servo
    # would refuse, so enabling would drive it to a stale goal instead. Nothing is enabled.
    bus.write_register(3, Reg.MAX_POSITION_LIMIT, 3000)
    emulator.place({1: 2048, 2: 2048, 3: 3100})
    with pytest.raises(
        ServoStatusError, match="servo 3: goal 3100 ticks outside its limits 0 .. 3000"
    ):
        bus.torque(True)
    assert [emulator.servo(i).table.get(Reg.TORQUE_ENABLE) for i in IDS] == [0, 0, 0]
