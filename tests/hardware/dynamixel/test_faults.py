"""Injected faults: every one is survived, counted, and reported with the servo's id.

A failed read raises CommError (a BusError) naming the servos and the number of tries;
it never returns a state assembled from a partial or corrupt reply, and the bus keeps
working once the fault is gone.
"""

from __future__ import annotations

import pytest

from hardware.bus import PositionGains
from hardware.dynamixel.control_table import HardwareErrorFlag, Reg
from hardware.dynamixel.driver import DynamixelBus
from hardware.emulator import ServoEmulator
from hardware.errors import BusError, CommError
from tests.support.servo_emulator import make_config
from tests.support.wait import wait_for


@pytest.mark.slow
@pytest.mark.parametrize("fault", ["drop_replies", "corrupt_replies", "wrong_id_replies"])
def test_one_bad_reply_is_retried_and_counted(bus: DynamixelBus, emulator, fault: str) -> None:
    emulator.place({1: 1000, 2: 2000, 3: 3000})
    emulator.inject(2, **{fault: 1})
    assert bus.read_ticks() == {1: 1000, 2: 2000, 3: 3000}
    stats = bus.stats
    # one failed try, retried (exactly one on a quiet machine; beside CPU hogs a reply of
    # the failed try can land late in the retry and fail it too, counted as it should be)
    assert stats.failed_tries == stats.retries >= 1 and stats.failures == 0, stats


@pytest.mark.slow  # three tries of a 1 s reply timeout per case
@pytest.mark.parametrize(
    ("fault", "reason"),
    [
        ("drop_replies", "There is no status packet"),
        ("corrupt_replies", "Incorrect status packet"),
        ("wrong_id_replies", "There is no status packet"),
    ],
)
def test_persistent_bad_replies_raise_naming_the_servo(
    patient_bus, emulator, fault, reason
) -> None:
    bus = patient_bus
    emulator.inject(2, **{fault: 3})
    with pytest.raises(CommError) as info:
        bus.read_state()
    error = info.value
    assert 2 in error.ids and 1 not in error.ids
    assert error.tries == 3 and reason in str(error)
    assert error.instruction == "sync read MOVING..PRESENT_TEMPERATURE"
    assert bus.stats.failures == 1 and bus.stats.failed_tries == 3
    assert bus.read_state().position_rad.shape == (3,)  # fault spent: the bus works again


@pytest.mark.slow  # reply timeouts of a silent servo
def test_unplugged_servo_fails_reads_and_writes_then_recovers(patient_bus, emulator) -> None:
    bus = patient_bus
    emulator.inject(3, unplugged=True)
    with pytest.raises(CommError, match="on servo 3 failed after 3 tries: servo 3: There is no"):
        bus.read_state()
    with pytest.raises(CommError, match="write POSITION_P_GAIN on servo 3"):
        bus.set_gains(PositionGains())
    assert [info.servo_id for info in bus.scan()] == [1, 2]
    emulator.inject(3, unplugged=False)
    assert not bus.read_state().faulted


def test_late_replies_time_out_then_the_bus_resynchronises(emulator: ServoEmulator) -> None:
    bus = DynamixelBus(make_config(emulator.port, rx_timeout_s=0.02, max_tries=2))
    bus.connect()
    try:
        emulator.place({1: 11, 2: 22, 3: 33})
        emulator.inject(2, delay_s=0.1)
        with pytest.raises(CommError) as info:
            bus.read_state()
        assert 2 in info.value.ids and info.value.tries == 2
        emulator.clear_faults()

        def resynchronised() -> bool:  # late replies land and are thrown away, then it reads
            try:
                return bus.read_ticks() == {1: 11, 2: 22, 3: 33}
            except CommError:  # a late reply still in the way, or a loaded machine's miss
                return False

        wait_for(resynchronised, "the bus to read the true ticks again")
    finally:
        bus.disconnect()


def test_a_short_delay_is_within_the_timeout(bus: DynamixelBus, emulator) -> None:
    emulator.inject(1, delay_s=0.002)
    bus.read_state()
    assert bus.stats.failed_tries == 0


def test_hardware_error_bit_is_reported_not_raised(bus, emulator) -> None:
    bus.torque(True)
    emulator.raise_hardware_error(1, HardwareErrorFlag.INPUT_VOLTAGE)
    state = bus.read_state()
    assert state.hardware_errors == (("input_voltage",), (), ())
    # Input voltage is not in the factory Shutdown mask (52): torque stays on.
    assert emulator.servo(1).table.get(Reg.TORQUE_ENABLE) == 1
    emulator.raise_hardware_error(3, HardwareErrorFlag.ELECTRICAL_SHOCK)
    assert bus.read_state().hardware_errors[2] == ("electrical_shock",)
    assert emulator.servo(3).table.get(Reg.TORQUE_ENABLE) == 0  # shut down


def test_faults_are_bus_errors_and_unknown_faults_are_refused(bus, emulator) -> None:
    assert issubclass(CommError, BusError)
    with pytest.raises(AttributeError, match="no fault named 'gremlins'"):
        emulator.inject(1, gremlins=True)


@pytest.mark.slow  # reply timeouts of a slow servo
def test_a_minimum_reply_wait_takes_answers_slower_than_the_sdk_timeout(
    emulator: ServoEmulator,
) -> None:
    """An emulator a loaded machine deschedules answers later than the SDK's ~34 ms status
    timeout: with ``min_reply_wait_s`` above its delay the bus reads and writes as usual;
    without it, the same delay is a failed read."""
    emulator.place({1: 1000, 2: 2000, 3: 3000})
    hasty = DynamixelBus(make_config(emulator.port, max_tries=1, min_reply_wait_s=0.0))
    hasty.connect()
    emulator.inject(2, delay_s=0.08)  # over the SDK's timeout for any packet here
    try:
        with pytest.raises(CommError, match="servo 2"):
            hasty.read_ticks()
    finally:
        hasty.disconnect()
    patient = DynamixelBus(make_config(emulator.port, min_reply_wait_s=1.0))
    patient.connect()
    try:
        assert patient.read_ticks() == {1: 1000, 2: 2000, 3: 3000}
        patient.set_gains(PositionGains())  # a write to each servo: answered too
        assert patient.stats.failures == 0
    finally:
        patient.disconnect()
    with pytest.raises(ValueError, match="min_reply_wait_s"):
        DynamixelBus(make_config(emulator.port, min_reply_wait_s=-1.0))
