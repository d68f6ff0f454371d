"""Guided homing on the emulated bus through the real dynamixel-sdk (hardware/homing.py):
homings on both sides of the encoder's 0/4095 seam, in Position and Extended Position
Control Mode. Limits -0.6 .. 1.4 rad = -391 .. +913 ticks (tests/hardware/test_seam.py)."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from hardware.bus import OperatingMode
from hardware.calibration import JointCalibration, load
from hardware.dynamixel.control_table import RAD_PER_TICK, Reg
from hardware.dynamixel.driver import DynamixelBus
from hardware.homing import home_bus
from hardware.seam import SeamError
from tests.support.servo_emulator import IDS
from tests.support.wait import wait_for


def with_joints(bus: DynamixelBus, direction: int) -> None:
    joints = tuple(JointCalibration(i, 2048, direction, -0.6, 1.4) for i in IDS)
    bus.config = replace(bus.config, joints=joints)


@pytest.mark.parametrize(
    ("raw", "direction", "ticks"),
    [
        (4000, 1, "3609 .. 4913"),
        (100, 1, "-291 .. 1013"),
        (3183, 1, "2792 .. 4096"),
        (4000, -1, "3087 .. 4391"),
        (100, -1, "-813 .. 491"),
        (912, -1, "-1 .. 1303"),
    ],
)
def test_homing_across_the_seam_is_refused_and_saves_nothing(
    bus, emulator, tmp_path: Path, raw: int, direction: int, ticks: str
) -> None:
    with_joints(bus, direction)
    emulator.place({1: 2048, 2: raw, 3: 2048})
    path = tmp_path / "robot.toml"
    path.write_text("[server]\nhttp_port = 8123\n")
    with pytest.raises(SeamError, match=f"servo 2 \\(joint 2\\).* {ticks} ticks.*seam"):
        home_bus(bus, path, 0.0, confirm=lambda prompt: None)
    assert path.read_text() == "[server]\nhttp_port = 8123\n"
    assert bus.config.joints[1].zero_offset_ticks == 2048  # the bus keeps its calibration


@pytest.mark.slow
@pytest.mark.parametrize(
    ("raw", "direction"), [(2048, 1), (391, 1), (3182, 1), (3500, -1), (913, -1), (3704, -1)]
)
def test_homing_inside_one_turn_is_saved_and_reaches_its_limits(
    bus, emulator, tmp_path: Path, raw: int, direction: int
) -> None:
    with_joints(bus, direction)
    emulator.place({i: raw for i in IDS})
    homed = home_bus(bus, tmp_path / "robot.toml", 0.0, confirm=lambda prompt: None)
    assert [c.zero_offset_ticks for c in homed] == [raw] * 3
    assert load(tmp_path / "robot.toml") == homed
    bus.write_position_limits()
    bus.torque(True)
    for goal in (1.4, -0.6):  # both ends: neither refused by the servo nor by the driver
        reach(bus, [goal] * 3)


def test_homing_reads_a_count_that_ran_past_the_seam_as_the_servo_will(
    bus, emulator, tmp_path: Path
) -> None:
    # With torque off the count runs on: a shaft at 904 may read 904 + 4096 = 5000. Torque
    # on in Position Control Mode restarts it at 904, so 904 is the zero to save.
    with_joints(bus, 1)
    emulator.place({1: 5000, 2: 2048, 3: 2048})
    assert bus.read_ticks()[1] == 5000
    homed = home_bus(bus, tmp_path / "robot.toml", 0.0, confirm=lambda prompt: None)
    assert homed[0].zero_offset_ticks == 904
    bus.torque(True)  # holds at 904, the goal the restarted count means
    assert bus.read_ticks()[1] == 904
    np.testing.assert_allclose(bus.read_state().position_rad, [0.0, 0.0, 0.0], atol=RAD_PER_TICK)


ON_ITS_TURN_RAD = 0.05


@pytest.mark.slow
def test_extended_position_mode_homes_across_the_seam_and_keeps_its_turn(
    bus, emulator, tmp_path: Path
) -> None:
    with_joints(bus, 1)
    bus.set_operating_mode(OperatingMode.EXTENDED_POSITION)
    emulator.place({1: 4000, 2: 2048, 3: 2048})
    homed = home_bus(bus, tmp_path / "robot.toml", 0.0, confirm=lambda prompt: None)
    assert homed[0].tick_limits() == (3609, 4913)
    bus.torque(True)
    reach(bus, [1.0, 0.0, 0.0])  # 4000 + 652 = 4652 ticks: through the seam
    bus.torque(False)
    # A power cycle (here a reboot) restarts the count at one turn: 4652 - 4096 = 556. The
    # driver puts the joint back on its turn with Homing Offset 4096.
    bus.reboot([1])
    assert emulator.servo(1).table.get(Reg.HOMING_OFFSET) == 4096
    # on its turn: a turn off would read 1.0 -/+ 6.28 rad; the relaxed link may sag a
    # few ticks meanwhile (more on a loaded machine), so the bound is a few degrees
    assert bus.read_state().position_rad[0] == pytest.approx(1.0, abs=ON_ITS_TURN_RAD)
    # ... and so does a fresh connect after the servo restarted its count at power-on
    with emulator.lock:
        emulator.servo(1).table.set(Reg.HOMING_OFFSET, 0)
        emulator.servo(1).restart_count()
    fresh = DynamixelBus(bus.config)
    fresh.connect()
    try:
        assert fresh.read_state().position_rad[0] == pytest.approx(1.0, abs=ON_ITS_TURN_RAD)
    finally:
        fresh.disconnect()


def reach(bus: DynamixelBus, goal: list[float]) -> None:
    def arrived():
        bus.write_goal(goal)
        state = bus.read_state()
        return state if np.allclose(state.position_rad, goal, atol=2 * RAD_PER_TICK) else None

    wait_for(
        arrived, f"the joints at {goal} rad ({math.degrees(goal[0]):.0f} deg)", 10.0, poll_s=0.01
    )
