"""dynamixel-sdk, unmodified, against the emulator: every instruction and the error codes."""

from __future__ import annotations

import dynamixel_sdk as sdk
import pytest

from hardware.dynamixel.control_table import HardwareErrorFlag, Reg
from hardware.dynamixel.protocol import StatusError
from hardware.emulator import ServoEmulator

OK = sdk.COMM_SUCCESS


@pytest.mark.slow
def test_ping_each_servo_and_miss_an_absent_one(sdk_port) -> None:
    port, ph = sdk_port
    for servo_id in (1, 2, 3):
        assert ph.ping(port, servo_id) == (1030, OK, 0)
    model, result, _ = ph.ping(port, 9)
    assert result == sdk.COMM_RX_TIMEOUT


@pytest.mark.slow
def test_broadcast_ping_finds_every_servo(sdk_port) -> None:
    port, ph = sdk_port
    found, result = ph.broadcastPing(port)
    assert result == OK
    assert {i: found[i][0] for i in found} == {1: 1030, 2: 1030, 3: 1030}


def test_read_and_write_1_2_4_byte_items(sdk_port, emulator: ServoEmulator) -> None:
    port, ph = sdk_port
    assert ph.write1ByteTxRx(port, 2, Reg.LED.address, 1) == (OK, 0)
    assert ph.read1ByteTxRx(port, 2, Reg.LED.address) == (1, OK, 0)
    assert ph.write2ByteTxRx(port, 2, Reg.POSITION_P_GAIN.address, 1234) == (OK, 0)
    assert ph.read2ByteTxRx(port, 2, Reg.POSITION_P_GAIN.address) == (1234, OK, 0)
    assert ph.write4ByteTxRx(port, 2, Reg.PROFILE_VELOCITY.address, 100_000 % 32768) == (OK, 0)
    assert ph.read4ByteTxRx(port, 2, Reg.PROFILE_VELOCITY.address) == (100_000 % 32768, OK, 0)
    assert emulator.servo(2).table.get(Reg.POSITION_P_GAIN) == 1234


@pytest.mark.parametrize(
    ("address", "size", "value", "error"),
    [
        (Reg.PRESENT_POSITION.address, 4, 0, StatusError.ACCESS),  # read-only
        (Reg.MODEL_NUMBER.address, 2, 1, StatusError.ACCESS),  # read-only EEPROM
        (66, 1, 0, StatusError.ACCESS),  # undefined address
        (Reg.OPERATING_MODE.address, 1, 2, StatusError.DATA_RANGE),  # no mode 2
        (Reg.ID.address, 1, 253, StatusError.DATA_RANGE),
        (Reg.GOAL_POSITION.address, 4, 4096, StatusError.DATA_LIMIT),  # above Max Position
        (Reg.GOAL_CURRENT.address, 2, 1194, StatusError.DATA_RANGE),
        (Reg.GOAL_POSITION.address, 2, 10, StatusError.DATA_LENGTH),  # half an item
    ],
)
def test_refused_writes_get_the_emanual_error(sdk_port, emulator, address, size, value, error):
    port, ph = sdk_port
    writable = slice(0, Reg.REALTIME_TICK.address)  # beyond it the servo updates itself
    before = bytes(emulator.servo(1).table.memory[writable])
    data = list(value.to_bytes(size, "little"))
    assert ph.writeTxRx(port, 1, address, size, data) == (OK, error)
    assert bytes(emulator.servo(1).table.memory[writable]) == before  # nothing applied


def test_goal_above_a_lowered_limit_is_a_data_limit_error(sdk_port) -> None:
    port, ph = sdk_port
    assert ph.write4ByteTxRx(port, 1, Reg.MAX_POSITION_LIMIT.address, 3000) == (OK, 0)
    assert ph.write4ByteTxRx(port, 1, Reg.GOAL_POSITION.address, 3001) == (
        OK,
        StatusError.DATA_LIMIT,
    )
    assert ph.write4ByteTxRx(port, 1, Reg.GOAL_POSITION.address, 3000) == (OK, 0)


def test_eeprom_is_locked_while_torque_is_on(sdk_port, emulator: ServoEmulator) -> None:
    port, ph = sdk_port
    assert ph.write1ByteTxRx(port, 3, Reg.TORQUE_ENABLE.address, 1) == (OK, 0)
    assert ph.write1ByteTxRx(port, 3, Reg.OPERATING_MODE.address, 1) == (OK, StatusError.ACCESS)
    assert emulator.servo(3).table.get(Reg.OPERATING_MODE) == 3
    assert ph.write1ByteTxRx(port, 3, Reg.TORQUE_ENABLE.address, 0) == (OK, 0)
    assert ph.write1ByteTxRx(port, 3, Reg.OPERATING_MODE.address, 1) == (OK, 0)


def test_reading_past_the_table_is_an_access_error(sdk_port) -> None:
    port, ph = sdk_port
    _, result, error = ph.readTxRx(port, 1, 140, 20)
    assert (result, error) == (OK, StatusError.ACCESS)


def test_reg_write_waits_for_action(sdk_port, emulator: ServoEmulator) -> None:
    port, ph = sdk_port
    assert ph.regWriteTxRx(port, 1, Reg.LED.address, 1, [1]) == (OK, 0)
    assert emulator.servo(1).table.get(Reg.LED) == 0
    assert ph.read1ByteTxRx(port, 1, Reg.REGISTERED_INSTRUCTION.address) == (1, OK, 0)
    assert ph.action(port, sdk.BROADCAST_ID) == OK  # broadcast: no status to wait for
    assert ph.read1ByteTxRx(port, 1, Reg.LED.address) == (1, OK, 0)
    assert ph.read1ByteTxRx(port, 1, Reg.REGISTERED_INSTRUCTION.address) == (0, OK, 0)


def test_reboot_clears_a_hardware_error(sdk_port, emulator: ServoEmulator) -> None:
    port, ph = sdk_port
    emulator.raise_hardware_error(2, HardwareErrorFlag.OVERHEATING)
    value, result, error = ph.read1ByteTxRx(port, 2, Reg.HARDWARE_ERROR_STATUS.address)
    assert (value, result, error) == (HardwareErrorFlag.OVERHEATING, OK, 0x80)  # alert bit
    assert ph.write1ByteTxRx(port, 2, Reg.TORQUE_ENABLE.address, 1) == (OK, 0x80)
    assert ph.read1ByteTxRx(port, 2, Reg.TORQUE_ENABLE.address)[0] == 0  # shut down
    assert ph.reboot(port, 2) == (OK, 0x80)  # the answer goes out before the reboot
    assert ph.read1ByteTxRx(port, 2, Reg.HARDWARE_ERROR_STATUS.address) == (0, OK, 0)


def test_factory_reset_all_returns_to_id_1(sdk_port, emulator: ServoEmulator) -> None:
    port, ph = sdk_port
    assert ph.factoryReset(port, 3, 0xFF) == (OK, 0)
    with emulator.lock:  # the reset follows its status packet; the lock waits for it
        assert emulator.servos[2].servo_id == 1
    assert ph.factoryReset(port, 2, 0x07) == (OK, StatusError.DATA_RANGE)


@pytest.mark.slow
def test_id_change_moves_the_servo(sdk_port) -> None:
    port, ph = sdk_port
    assert ph.write1ByteTxRx(port, 3, Reg.ID.address, 7) == (OK, 0)
    assert ph.ping(port, 7)[1] == OK
    assert ph.ping(port, 3)[1] == sdk.COMM_RX_TIMEOUT


@pytest.mark.slow
def test_status_return_level(sdk_port) -> None:
    port, ph = sdk_port
    assert ph.write1ByteTxRx(port, 1, Reg.STATUS_RETURN_LEVEL.address, 1) == (OK, 0)
    assert ph.write1ByteTxRx(port, 1, Reg.LED.address, 1)[0] == sdk.COMM_RX_TIMEOUT  # silent
    assert ph.read1ByteTxRx(port, 1, Reg.LED.address) == (1, OK, 0)  # reads still answer
    ph.write1ByteTxOnly(port, 1, Reg.STATUS_RETURN_LEVEL.address, 0)
    assert ph.read1ByteTxRx(port, 1, Reg.LED.address)[1] == sdk.COMM_RX_TIMEOUT
    assert ph.ping(port, 1)[1] == OK  # ping always answers


def test_factory_return_delay_still_answers(sdk_port, emulator: ServoEmulator) -> None:
    port, ph = sdk_port
    emulator.servo(1).table.set(Reg.RETURN_DELAY_TIME, 250)  # 500 us, as shipped
    assert ph.read1ByteTxRx(port, 1, Reg.RETURN_DELAY_TIME.address) == (250, OK, 0)


def test_sync_write_then_sync_read(sdk_port, emulator: ServoEmulator) -> None:
    port, ph = sdk_port
    writer = sdk.GroupSyncWrite(port, ph, Reg.PROFILE_VELOCITY.address, 4)
    for servo_id in (1, 2, 3):
        assert writer.addParam(servo_id, list((10 * servo_id).to_bytes(4, "little")))
    assert writer.txPacket() == OK
    reader = sdk.GroupSyncRead(port, ph, Reg.PROFILE_VELOCITY.address, 4)
    for servo_id in (1, 2, 3):
        reader.addParam(servo_id)
    assert reader.txRxPacket() == OK
    assert [reader.getData(i, Reg.PROFILE_VELOCITY.address, 4) for i in (1, 2, 3)] == [10, 20, 30]
    emulator.place({1: 100, 2: 200, 3: 300})
    assert reader.fastSyncRead() == OK
    assert [reader.getData(i, Reg.PROFILE_VELOCITY.address, 4) for i in (1, 2, 3)] == [10, 20, 30]


def test_fast_sync_read_of_positions(sdk_port, emulator: ServoEmulator) -> None:
    port, ph = sdk_port
    emulator.place({1: 100, 2: 2000, 3: 4000})
    reader = sdk.GroupSyncRead(port, ph, Reg.PRESENT_POSITION.address, 4)
    for servo_id in (1, 2, 3):
        reader.addParam(servo_id)
    assert reader.fastSyncRead() == OK
    assert [reader.getData(i, Reg.PRESENT_POSITION.address, 4) for i in (1, 2, 3)] == [
        100,
        2000,
        4000,
    ]


def test_bulk_write_then_bulk_and_fast_bulk_read(sdk_port, emulator: ServoEmulator) -> None:
    port, ph = sdk_port
    writer = sdk.GroupBulkWrite(port, ph)
    assert writer.addParam(1, Reg.LED.address, 1, [1])
    assert writer.addParam(2, Reg.POSITION_P_GAIN.address, 2, [0x34, 0x12])
    assert writer.txPacket() == OK
    emulator.place({3: 777})
    reader = sdk.GroupBulkRead(port, ph)
    reader.addParam(1, Reg.LED.address, 1)
    reader.addParam(2, Reg.POSITION_P_GAIN.address, 2)
    reader.addParam(3, Reg.PRESENT_POSITION.address, 4)
    assert reader.txRxPacket() == OK
    expected = [1, 0x1234, 777]
    items = [(1, Reg.LED), (2, Reg.POSITION_P_GAIN), (3, Reg.PRESENT_POSITION)]
    assert [reader.getData(i, r.address, r.size) for i, r in items] == expected
    assert reader.fastBulkRead() == OK
    assert [reader.getData(i, r.address, r.size) for i, r in items] == expected


def test_homing_offset_shifts_present_position(sdk_port, emulator: ServoEmulator) -> None:
    port, ph = sdk_port
    emulator.place({1: 1000})
    assert ph.write4ByteTxRx(port, 1, Reg.HOMING_OFFSET.address, 500) == (OK, 0)
    assert ph.read4ByteTxRx(port, 1, Reg.PRESENT_POSITION.address) == (1500, OK, 0)
    assert ph.write4ByteTxRx(port, 1, Reg.HOMING_OFFSET.address, (-200) & 0xFFFFFFFF) == (OK, 0)
    value, result, _ = ph.read4ByteTxRx(port, 1, Reg.PRESENT_POSITION.address)
    assert (value, result) == (800, OK)


def test_position_limits_bind_position_mode_only(sdk_port) -> None:
    port, ph = sdk_port
    assert ph.write1ByteTxRx(port, 1, Reg.OPERATING_MODE.address, 5) == (OK, 0)
    assert ph.write4ByteTxRx(port, 1, Reg.GOAL_POSITION.address, 9000) == (OK, 0)
    assert ph.write1ByteTxRx(port, 2, Reg.OPERATING_MODE.address, 4) == (OK, 0)
    assert ph.write4ByteTxRx(port, 2, Reg.GOAL_POSITION.address, (-9000) & 0xFFFFFFFF) == (OK, 0)
