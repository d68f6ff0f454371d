"""The reset path: a latched hardware error is named from the alerting servo's Hardware
Error Status register, a reboot clears it and returns only once the servo answers again,
and torque can then be enabled. Every hardware error bit goes through it."""

from __future__ import annotations

import pytest

from hardware.dynamixel.control_table import HardwareErrorFlag, Reg
from hardware.dynamixel.driver import DynamixelBus
from hardware.dynamixel.protocol import ALERT_BIT
from hardware.emulator import ServoEmulator
from hardware.errors import CommError, HardwareError
from tests.support.servo_emulator import make_config

BOOT_S = 0.2  # the emulated servo's deaf time after a Reboot: longer than a read's 3 tries

# (bit, its name, whether the factory Shutdown mask (52) turns torque off for it)
BITS = [
    (HardwareErrorFlag.INPUT_VOLTAGE, "input_voltage", False),  # bit 0
    (HardwareErrorFlag.OVERHEATING, "overheating", True),  # bit 2
    (HardwareErrorFlag.MOTOR_ENCODER, "motor_encoder", False),  # bit 3
    (HardwareErrorFlag.ELECTRICAL_SHOCK, "electrical_shock", True),  # bit 4
    (HardwareErrorFlag.OVERLOAD, "overload", True),  # bit 5
]


@pytest.mark.slow
@pytest.mark.parametrize(("flag", "name", "shuts_down"), BITS, ids=[b[1] for b in BITS])
def test_every_hardware_error_is_named_and_a_reboot_clears_it(
    bus: DynamixelBus, emulator: ServoEmulator, flag, name: str, shuts_down: bool
) -> None:
    bus.torque(True)
    emulator.inject(1, boot_s=BOOT_S)
    emulator.raise_hardware_error(1, flag)
    assert bus.read_state().hardware_errors == ((name,), (), ())
    assert emulator.servo(1).table.get(Reg.TORQUE_ENABLE) == (0 if shuts_down else 1)
    with pytest.raises(HardwareError, match=f"servo 1: {name}\\)$"):
        bus.torque(True)  # a latched servo refuses torque, by the register's names only
    bus.reboot([1])
    # reboot() returned, so servo 1 answers: without the wait, this read would meet a servo
    # still booting (deaf for longer than the read's three tries)
    state = bus.read_state()
    assert not state.faulted and state.hardware_errors == ((), (), ())
    bus.torque(True)
    servo = emulator.servo(1)
    assert servo.reboots == 1 and servo.table.get(Reg.TORQUE_ENABLE) == 1
    assert emulator.servo(2).reboots == emulator.servo(3).reboots == 0


@pytest.mark.slow
def test_two_latched_servos_reboot_together(bus: DynamixelBus, emulator: ServoEmulator) -> None:
    for servo_id in (1, 3):
        emulator.inject(servo_id, boot_s=BOOT_S)
    emulator.raise_hardware_error(1, HardwareErrorFlag.OVERLOAD)
    emulator.raise_hardware_error(3, HardwareErrorFlag.OVERHEATING | HardwareErrorFlag.OVERLOAD)
    assert bus.read_state().hardware_errors == (("overload",), (), ("overheating", "overload"))
    bus.reboot([1, 3])
    assert not bus.read_state().faulted
    assert [emulator.servo(i).reboots for i in (1, 2, 3)] == [1, 0, 1]


@pytest.mark.slow
def test_a_lost_reboot_status_is_not_answered_by_another_reboot(
    bus: DynamixelBus, emulator: ServoEmulator
) -> None:
    emulator.raise_hardware_error(2, HardwareErrorFlag.OVERLOAD)
    emulator.inject(2, drop_replies=1, boot_s=BOOT_S)  # it reboots, its status is lost
    bus.reboot([2])
    assert emulator.servo(2).reboots == 1  # the register said it had rebooted: no second
    assert not bus.read_state().faulted


@pytest.mark.slow
def test_an_unheard_reboot_is_sent_again(bus: DynamixelBus, emulator: ServoEmulator) -> None:
    emulator.raise_hardware_error(2, HardwareErrorFlag.OVERLOAD)
    emulator.inject(2, ignore_requests=1)  # the first Reboot never reaches it
    bus.reboot([2])
    assert emulator.servo(2).reboots == 1
    assert not bus.read_state().faulted


@pytest.mark.slow  # pings wait out their reply waits (wall time)
def test_a_servo_that_does_not_come_back_is_named(emulator: ServoEmulator) -> None:
    bus = DynamixelBus(make_config(emulator.port, reboot_timeout_s=0.3))
    bus.connect()
    try:
        emulator.inject(1, boot_s=60.0)
        with pytest.raises(CommError, match="reboot on servo 1 failed: did not answer a ping"):
            bus.reboot([1])
        with pytest.raises(CommError, match="servo 42"):
            bus.reboot([42])  # no such servo
    finally:
        bus.disconnect()


def test_an_alert_bit_with_nothing_latched_names_nothing(
    bus: DynamixelBus, emulator: ServoEmulator
) -> None:
    # The names come from the Hardware Error Status register alone: a status packet's alert
    # bit over a register that reads 0 neither names a fault nor refuses torque.
    with emulator.lock:
        emulator.servo(1).error_byte = lambda error: int(error) | ALERT_BIT  # type: ignore
    assert bus.read_state().hardware_errors == ((), (), ())
    bus.torque(True)
    assert emulator.servo(1).table.get(Reg.TORQUE_ENABLE) == 1


@pytest.mark.parametrize(("flag", "name", "shuts_down"), BITS, ids=[b[1] for b in BITS])
def test_the_state_carries_the_torque_each_servo_reads_back(
    bus: DynamixelBus, emulator: ServoEmulator, flag, name: str, shuts_down: bool
) -> None:
    assert bus.read_state().torque_enabled == (False, False, False)  # as connect read it
    bus.torque(True)
    assert bus.read_state().torque_enabled == (True, True, True)
    emulator.raise_hardware_error(1, flag)
    state = bus.read_state()
    # what servo 1's Torque Enable (64) reads after the error, not what was last written
    assert state.hardware_errors == ((name,), (), ())
    assert state.torque_enabled == (not shuts_down, True, True)
    bus.reboot([1])
    assert bus.read_state().torque_enabled == (False, True, True)  # back with torque off
    bus.torque(False)
    assert bus.read_state().torque_enabled == (False, False, False)


def test_torque_written_behind_the_bus_is_read_back(
    bus: DynamixelBus, emulator: ServoEmulator
) -> None:
    bus.torque(True)
    bus.write_register(2, Reg.TORQUE_ENABLE, 0)
    assert bus.read_state().torque_enabled == (True, False, True)
