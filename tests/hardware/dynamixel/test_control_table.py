"""The XM430-W210 control table and the unit conversions at the bus boundary."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hardware.dynamixel.control_table import (
    STATE_BLOCK_SIZE,
    STATE_BLOCK_START,
    Access,
    Area,
    HardwareErrorFlag,
    Reg,
    acceleration_to_rad_s2,
    ampere_to_current,
    current_to_ampere,
    decode,
    encode,
    hardware_error_names,
    rad_s2_to_acceleration,
    rad_s_to_velocity,
    to_signed,
    velocity_to_rad_s,
    voltage_to_volt,
)

# (address, size, access) from the XM430-W210 e-manual control table.
EMANUAL_ITEMS = {
    Reg.MODEL_NUMBER: (0, 2, Access.R),
    Reg.FIRMWARE_VERSION: (6, 1, Access.R),
    Reg.ID: (7, 1, Access.RW),
    Reg.BAUD_RATE: (8, 1, Access.RW),
    Reg.RETURN_DELAY_TIME: (9, 1, Access.RW),
    Reg.DRIVE_MODE: (10, 1, Access.RW),
    Reg.OPERATING_MODE: (11, 1, Access.RW),
    Reg.HOMING_OFFSET: (20, 4, Access.RW),
    Reg.TEMPERATURE_LIMIT: (31, 1, Access.RW),
    Reg.CURRENT_LIMIT: (38, 2, Access.RW),
    Reg.VELOCITY_LIMIT: (44, 4, Access.RW),
    Reg.MAX_POSITION_LIMIT: (48, 4, Access.RW),
    Reg.MIN_POSITION_LIMIT: (52, 4, Access.RW),
    Reg.SHUTDOWN: (63, 1, Access.RW),
    Reg.TORQUE_ENABLE: (64, 1, Access.RW),
    Reg.STATUS_RETURN_LEVEL: (68, 1, Access.RW),
    Reg.REGISTERED_INSTRUCTION: (69, 1, Access.R),
    Reg.HARDWARE_ERROR_STATUS: (70, 1, Access.R),
    Reg.VELOCITY_I_GAIN: (76, 2, Access.RW),
    Reg.VELOCITY_P_GAIN: (78, 2, Access.RW),
    Reg.POSITION_D_GAIN: (80, 2, Access.RW),
    Reg.POSITION_I_GAIN: (82, 2, Access.RW),
    Reg.POSITION_P_GAIN: (84, 2, Access.RW),
    Reg.FEEDFORWARD_2ND_GAIN: (88, 2, Access.RW),
    Reg.FEEDFORWARD_1ST_GAIN: (90, 2, Access.RW),
    Reg.GOAL_PWM: (100, 2, Access.RW),
    Reg.GOAL_CURRENT: (102, 2, Access.RW),
    Reg.GOAL_VELOCITY: (104, 4, Access.RW),
    Reg.PROFILE_ACCELERATION: (108, 4, Access.RW),
    Reg.PROFILE_VELOCITY: (112, 4, Access.RW),
    Reg.GOAL_POSITION: (116, 4, Access.RW),
    Reg.MOVING: (122, 1, Access.R),
    Reg.PRESENT_PWM: (124, 2, Access.R),
    Reg.PRESENT_CURRENT: (126, 2, Access.R),
    Reg.PRESENT_VELOCITY: (128, 4, Access.R),
    Reg.PRESENT_POSITION: (132, 4, Access.R),
    Reg.VELOCITY_TRAJECTORY: (136, 4, Access.R),
    Reg.POSITION_TRAJECTORY: (140, 4, Access.R),
    Reg.PRESENT_INPUT_VOLTAGE: (144, 2, Access.R),
    Reg.PRESENT_TEMPERATURE: (146, 1, Access.R),
}


@pytest.mark.parametrize("reg", list(EMANUAL_ITEMS))
def test_items_sit_where_the_emanual_puts_them(reg: Reg) -> None:
    address, size, access = EMANUAL_ITEMS[reg]
    assert (reg.address, reg.size, reg.value.access) == (address, size, access)


def test_items_do_not_overlap_and_eeprom_ends_before_torque_enable() -> None:
    spans = sorted((reg.address, reg.address + reg.size, reg) for reg in Reg)
    for (_, end, first), (start, _, second) in zip(spans, spans[1:], strict=False):
        assert end <= start, f"{first.name} overlaps {second.name}"
    for reg in Reg:
        expected = Area.EEPROM if reg.address < Reg.TORQUE_ENABLE.address else Area.RAM
        assert reg.value.area is expected, reg.name


def test_factory_defaults_of_the_xm430_w210() -> None:
    assert Reg.MODEL_NUMBER.value.default == 1030
    assert Reg.RETURN_DELAY_TIME.value.default == 250
    assert Reg.OPERATING_MODE.value.default == 3
    assert Reg.POSITION_P_GAIN.value.default == 800
    assert Reg.CURRENT_LIMIT.value.default == 1193
    assert (STATE_BLOCK_START, STATE_BLOCK_SIZE) == (122, 25)


@given(st.integers(-(2**31), 2**31 - 1))
def test_signed_32_bit_round_trip(value: int) -> None:
    assert decode(Reg.PRESENT_POSITION, encode(Reg.PRESENT_POSITION, value)) == value


def test_signed_decoding_examples() -> None:
    assert to_signed(0xFFFFFFFF, 4) == -1
    assert to_signed(0x80000000, 4) == -(2**31)
    assert to_signed(0xFFFF, 2) == -1
    assert decode(Reg.PRESENT_CURRENT, b"\x9c\xff") == -100
    assert decode(Reg.PRESENT_INPUT_VOLTAGE, b"\x78\x00") == 120  # unsigned item


def test_unit_conversions_match_the_datasheet() -> None:
    assert velocity_to_rad_s(1) == pytest.approx(0.229 * 2 * math.pi / 60)
    assert current_to_ampere(1193) == pytest.approx(3.209, abs=1e-3)
    assert voltage_to_volt(120) == pytest.approx(12.0)
    assert acceleration_to_rad_s2(1) == pytest.approx(214.577 * 2 * math.pi / 3600)


@given(st.integers(-1023, 1023))
def test_velocity_units_round_trip(units: int) -> None:
    assert rad_s_to_velocity(velocity_to_rad_s(units)) == units


@given(st.integers(-1193, 1193))
def test_current_units_round_trip(units: int) -> None:
    assert ampere_to_current(current_to_ampere(units)) == units


@given(st.integers(0, 32767))
def test_acceleration_units_round_trip(units: int) -> None:
    assert rad_s2_to_acceleration(acceleration_to_rad_s2(units)) == units


def test_hardware_error_names() -> None:
    bits = HardwareErrorFlag.OVERLOAD | HardwareErrorFlag.INPUT_VOLTAGE
    assert hardware_error_names(int(bits)) == ("input_voltage", "overload")
    assert hardware_error_names(0) == ()
    assert hardware_error_names(0x02) == ("bit 1",)
