"""Current-based Position Control Mode (Operating Mode 5) through the hardware layer.

The driver on dynamixel-sdk against the emulated XM430 (register values computed by hand:
Goal Current counts 2.69 mA units), the XM430 model's current limiter, and the twin behind
SimBus in simulated time: in mode 5 the motor current, and so the output torque, never
exceeds the Goal Current, whatever the joint is pushed against; in Position Control Mode
the same push draws more.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import mujoco
import numpy as np
import pytest

from hardware.bus import OperatingMode, goal_current_units
from hardware.dynamixel.control_table import AMPERE_PER_CURRENT_UNIT, Reg
from hardware.dynamixel.driver import DynamixelBus
from hardware.emulator import ServoEmulator
from hardware.errors import BusError, ServoStatusError
from hardware.shaft_motion import MotionCommand, MotionState, SimpleServoModel
from hardware.sim.process_bus import ProcessSimBus
from hardware.sim.sim_bus import SimBus, SimBusConfig
from hardware.sim.xm430 import XM430_W210, Xm430
from tests.support.servo_emulator import IDS

UNIT = AMPERE_PER_CURRENT_UNIT  # 2.69 mA
FULL_LIMIT_UNITS = 1193  # the XM430-W210's factory Current Limit (38)


# -- the shared check ---------------------------------------------------------------------
def test_goal_current_units_round_to_whole_units_and_name_the_joint() -> None:
    # 1.0 / 0.00269 = 371.75 -> 372; 0.5 / 0.00269 = 185.87 -> 186; 3.209 -> 1192.94 -> 1193
    assert goal_current_units([1.0, 0.5, 3.209], [1193] * 3, UNIT) == [372, 186, 1193]
    assert goal_current_units([0.0], [0], UNIT) == [0]
    with pytest.raises(ValueError, match=r"joint 2: 1\.5 A is above its Current Limit 1\.345 A"):
        goal_current_units([1.0, 1.5, 1.0], [1193, 500, 1193], UNIT)
    with pytest.raises(ValueError, match="joint 3: -0.1 A must be finite and >= 0"):
        goal_current_units([1.0, 1.0, -0.1], [1193] * 3, UNIT)
    with pytest.raises(ValueError, match="joint 1: nan A"):
        goal_current_units([math.nan, 1.0, 1.0], [1193] * 3, UNIT)
    with pytest.raises(ValueError, match="2 joints: the bus has 3"):
        goal_current_units([1.0, 1.0], [1193] * 3, UNIT)


# -- the driver on the emulated servos ----------------------------------------------------
def goal_units(emulator: ServoEmulator) -> list[int]:
    return [emulator.servo(i).table.get(Reg.GOAL_CURRENT) for i in IDS]


def test_the_driver_writes_mode_5_and_goal_current_as_register_values(
    bus: DynamixelBus, emulator: ServoEmulator
) -> None:
    bus.set_operating_mode(OperatingMode.CURRENT_BASED_POSITION)
    assert [emulator.servo(i).table.get(Reg.OPERATING_MODE) for i in IDS] == [5, 5, 5]
    assert [bus.read_register(i, Reg.OPERATING_MODE) for i in IDS] == [5, 5, 5]
    bus.set_goal_current([1.0, 0.5, 3.209])
    assert goal_units(emulator) == [372, 186, 1193]
    assert bus.read_goal_current() == pytest.approx([372 * UNIT, 186 * UNIT, 1193 * UNIT])
    # a RAM item: the firmware takes it with torque on
    bus.torque(True)
    bus.set_goal_current([0.2, 0.2, 0.2])  # 74.35 -> 74
    assert goal_units(emulator) == [74, 74, 74]


def test_the_driver_refuses_a_goal_current_above_the_servos_current_limit(
    bus: DynamixelBus, emulator: ServoEmulator
) -> None:
    bus.write_register(2, Reg.CURRENT_LIMIT, 500)  # EEPROM, torque off: 1.345 A
    bus.set_goal_current([0.5, 0.5, 0.5])
    before = goal_units(emulator)
    with pytest.raises(ValueError, match=r"joint 2: 1\.5 A is above its Current Limit 1\.345 A"):
        bus.set_goal_current([1.0, 1.5, 1.0])
    assert goal_units(emulator) == before  # nothing written, not even joint 1
    with pytest.raises(ValueError, match="joint 1: -0.5 A"):
        bus.set_goal_current([-0.5, 0.5, 0.5])
    with pytest.raises(ValueError, match="2 joints"):
        bus.set_goal_current([0.5, 0.5])
    # the emulated firmware's own check agrees: a raw write above the limit is refused
    with pytest.raises(ServoStatusError, match="servo 2"):
        bus.write_register(2, Reg.GOAL_CURRENT, 501)


def test_a_mode_change_needs_torque_off_and_resets_goal_current_to_the_limit(
    bus: DynamixelBus, emulator: ServoEmulator
) -> None:
    assert goal_units(emulator) == [FULL_LIMIT_UNITS] * 3  # at power-on, as the firmware
    bus.set_goal_current([0.3, 0.3, 0.3])
    bus.torque(True)
    with pytest.raises(ServoStatusError, match="access error"):
        bus.set_operating_mode(OperatingMode.CURRENT_BASED_POSITION)
    assert [emulator.servo(i).table.get(Reg.OPERATING_MODE) for i in IDS] == [3, 3, 3]
    bus.torque(False)
    bus.set_operating_mode(OperatingMode.CURRENT_BASED_POSITION)
    assert goal_units(emulator) == [FULL_LIMIT_UNITS] * 3  # so: goal current after the mode


def test_the_emulators_simple_model_bounds_its_current_by_goal_current_in_mode_5() -> None:
    model = SimpleServoModel()
    for mode, bound in (
        (OperatingMode.CURRENT_BASED_POSITION, 0.2),
        (OperatingMode.POSITION, 3.21),
    ):
        model.reset([0.0])
        cmd = MotionCommand(True, mode, goal_position_rad=3.0, goal_current_a=0.2)
        states: list[MotionState] = []
        for _ in range(50):
            states += model.step(0.002, [cmd])
        peak = max(abs(s.current_a) for s in states)
        assert peak == pytest.approx(bound)  # a far goal saturates at the bound


# -- the XM430 model's limiter ------------------------------------------------------------
@pytest.mark.parametrize(
    ("mode", "goal_a", "expected_a"),
    [
        (OperatingMode.CURRENT_BASED_POSITION, 0.5, 0.5),
        (OperatingMode.CURRENT_BASED_POSITION, -0.5, 0.5),  # the firmware takes |Goal Current|
        (OperatingMode.CURRENT_BASED_POSITION, 3.0, 1.0),  # never above the Current Limit
    ],
)
def test_the_xm430_model_bounds_current_by_min_of_goal_current_and_current_limit(
    mode: OperatingMode, goal_a: float, expected_a: float
) -> None:
    servo = Xm430()
    cmd = MotionCommand(True, mode, 2.0, goal_current_a=goal_a, current_limit_a=1.0)
    for speed in (0.0, 1.5, -1.5):  # the limiter accounts for the back-EMF
        out = servo.step(cmd, 0.0, speed)
        assert out.current_a == pytest.approx(expected_a)
        assert out.torque_nm == pytest.approx(XM430_W210.torque_constant_nm_a * expected_a)
    position = Xm430().step(
        MotionCommand(True, OperatingMode.POSITION, 2.0, current_limit_a=1.0), 0.0, 0.0
    )
    assert position.current_a > 2.0  # Position Control Mode: the PWM alone bounds it


# -- the twin behind SimBus, in simulated time ---------------------------------------------
@pytest.fixture
def sim() -> Iterator[SimBus]:
    bus = SimBus(SimBusConfig(realtime=False))
    bus.connect()
    yield bus
    bus.disconnect()


def test_simbus_goal_current_reaches_the_twins_commands(sim: SimBus) -> None:
    limit = FULL_LIMIT_UNITS * UNIT
    assert [c.goal_current_a for c in sim.twin.commands] == pytest.approx([limit] * 3)
    sim.set_operating_mode(OperatingMode.CURRENT_BASED_POSITION)
    sim.set_goal_current([0.3, 1.0, 0.5])  # 111.52 -> 112, 371.75 -> 372, 185.87 -> 186
    expected = [112 * UNIT, 372 * UNIT, 186 * UNIT]
    assert [c.goal_current_a for c in sim.twin.commands] == pytest.approx(expected, abs=1e-12)
    assert sim.read_goal_current() == pytest.approx(expected, abs=1e-12)
    assert all(c.mode is OperatingMode.CURRENT_BASED_POSITION for c in sim.twin.commands)
    with pytest.raises(ValueError, match=r"joint 3: 3\.3 A is above its Current Limit 3\.209 A"):
        sim.set_goal_current([0.3, 0.3, 3.3])
    assert sim.read_goal_current() == pytest.approx(expected, abs=1e-12)
    sim.torque(True)
    sim.set_goal_current([0.4, 0.4, 0.4])  # with torque on, as the firmware
    with pytest.raises(BusError, match="turn torque off"):
        sim.set_operating_mode(OperatingMode.POSITION)
    sim.torque(False)
    sim.set_operating_mode(OperatingMode.POSITION)  # a mode change: back to the limit
    assert sim.read_goal_current() == pytest.approx([limit] * 3)


def pushed(sim: SimBus, mode: OperatingMode, goal_a: float, force_n: float) -> dict:
    """Hold the home pose in `mode`, then push the platform down with `force_n` [N] and
    ask every joint 0.8 rad up (far from where it can go under the push); sample every
    5 ms of simulated time for 1 s. Returns the Present Currents [A] (samples, 3), the
    servo models' torques [N m] (samples, 3), and the goal and final joint angles [rad].

    5 N is a push that 0.3 A cannot lift but that never back-drives a joint near its
    no-load speed: a joint driven faster than that (e.g. 15 N here, about 10 rad/s) has
    more back-EMF than the PWM can oppose and draws more than the Goal Current, on the
    twin as on a real servo, whose limiter is also only as strong as its supply."""
    sim.set_operating_mode(mode)
    sim.set_goal_current([goal_a] * 3)
    sim.torque(True)
    sim.advance(0.2)
    start = sim.read_state().position_rad
    body = mujoco.mj_name2id(sim.twin.model, mujoco.mjtObj.mjOBJ_BODY, "platform")
    sim.twin.data.xfrc_applied[body, 2] = -force_n
    sim.write_goal(start - 0.8)
    currents, torques = [], []
    for _ in range(200):
        sim.advance(0.005)
        state = sim.read_state()
        assert not state.faulted
        currents.append(state.current_a)
        torques.append([o.torque_nm for o in sim.twin.outputs])
    final = sim.read_state().position_rad
    return {
        "current": np.abs(currents),
        "torque": np.abs(torques),
        "goal": start - 0.8,
        "final": final,
    }


def test_in_mode_5_a_pushed_joint_draws_no_more_than_its_goal_current(sim: SimBus) -> None:
    goal = 112 * UNIT  # 0.3 A asked, as written
    run = pushed(sim, OperatingMode.CURRENT_BASED_POSITION, 0.3, force_n=5.0)
    assert run["current"].max() <= goal + UNIT  # Present Current: one quantum
    assert run["current"].max() >= goal - UNIT  # and it does push with all it is allowed
    kt = XM430_W210.torque_constant_nm_a
    assert run["torque"].max() <= kt * goal * (1 + 1e-9)  # torque bound: Kt * Goal Current
    assert np.all(run["final"] > run["goal"] + 0.5)  # it gave way: nowhere near its goal


def test_in_position_mode_the_same_push_draws_more(sim: SimBus) -> None:
    run = pushed(sim, OperatingMode.POSITION, 0.3, force_n=5.0)
    assert run["current"].max() > 2 * 0.3  # Goal Current is no limit in mode 3
    assert run["final"] == pytest.approx(run["goal"], abs=0.05)  # it lifted the push


def test_the_process_bus_passes_goal_current_to_the_simulator_process() -> None:
    process = ProcessSimBus(SimBusConfig())
    process.connect()
    try:
        process.set_operating_mode(OperatingMode.CURRENT_BASED_POSITION)
        process.set_goal_current([0.3, 1.0, 0.5])
        assert process.read_goal_current() == pytest.approx([112 * UNIT, 372 * UNIT, 186 * UNIT])
        with pytest.raises(ValueError, match="joint 2: 3.5 A"):
            process.set_goal_current([0.3, 3.5, 0.5])
        assert process.read_goal_current() == pytest.approx([112 * UNIT, 372 * UNIT, 186 * UNIT])
    finally:
        process.disconnect()
