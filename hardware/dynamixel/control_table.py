"""XM430-W210 control table as data, and the unit conversions at the bus boundary.

The table follows the ROBOTIS e-manual (XM430-W210, Protocol 2.0, firmware 45+). Both the
driver (hardware/dynamixel/driver.py) and the emulator (hardware/emulator/memory.py) read it,
so an address typo would show up on both sides of the tests rather than hide behind one of
them.
Everything above hardware/ sees SI units; ticks and raw units stop here.
"""

from __future__ import annotations

import enum
import functools
import logging
import math
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

# Re-exported for the table's readers: Operating Mode (11) takes the ServoBus interface's
# OperatingMode values, and position registers count the encoder's ticks.
from hardware.bus import OperatingMode as OperatingMode
from hardware.encoder import RAD_PER_TICK as RAD_PER_TICK
from hardware.encoder import TICKS_PER_REV as TICKS_PER_REV

MODEL_NUMBER_XM430_W210 = 1030
VELOCITY_UNIT_RPM = 0.229
RAD_S_PER_VELOCITY_UNIT = VELOCITY_UNIT_RPM * 2.0 * math.pi / 60.0
AMPERE_PER_CURRENT_UNIT = 2.69e-3
VOLT_PER_VOLTAGE_UNIT = 0.1
# Profile Acceleration unit of the X series in velocity-based profile: 214.577 rev/min^2.
RAD_S2_PER_ACCELERATION_UNIT = 214.577 * 2.0 * math.pi / 3600.0
SECONDS_PER_RETURN_DELAY_UNIT = 2e-6


# A register value or a column of them (one per servo): the SI conversions take either.
_Units = TypeVar("_Units", float, np.ndarray)


class Access(enum.Enum):
    R = "R"
    RW = "RW"


class Area(enum.Enum):
    EEPROM = "EEPROM"  # locked while Torque Enable is 1
    RAM = "RAM"


@dataclass(frozen=True)
class Register:
    """One control-table item: address [byte], size [bytes], access, area and value range.

    `low`/`high` is the range the e-manual gives (Data Range Error outside it); `limit`
    names the register whose value bounds this one (Data Limit Error outside it).
    """

    address: int
    size: int
    access: Access
    area: Area
    default: int = 0
    low: int = 0
    high: int = 0
    signed: bool = False

    def __post_init__(self) -> None:
        if self.size not in (1, 2, 4):
            raise ValueError(f"register size {self.size} is not 1, 2 or 4 bytes")


_R, _RW, _E, _M = Access.R, Access.RW, Area.EEPROM, Area.RAM


class Reg(enum.Enum):
    """The XM430-W210 control table, name -> Register(address, size, access, area, ...)."""

    MODEL_NUMBER = Register(0, 2, _R, _E, MODEL_NUMBER_XM430_W210)
    MODEL_INFORMATION = Register(2, 4, _R, _E, 0)
    FIRMWARE_VERSION = Register(6, 1, _R, _E, 46)
    ID = Register(7, 1, _RW, _E, 1, 0, 252)
    BAUD_RATE = Register(8, 1, _RW, _E, 1, 0, 7)
    RETURN_DELAY_TIME = Register(9, 1, _RW, _E, 250, 0, 254)
    DRIVE_MODE = Register(10, 1, _RW, _E, 0, 0, 13)
    OPERATING_MODE = Register(11, 1, _RW, _E, 3, 0, 16)
    SECONDARY_ID = Register(12, 1, _RW, _E, 255, 0, 255)
    PROTOCOL_TYPE = Register(13, 1, _RW, _E, 2, 1, 2)
    HOMING_OFFSET = Register(20, 4, _RW, _E, 0, -1044479, 1044479, signed=True)
    MOVING_THRESHOLD = Register(24, 4, _RW, _E, 10, 0, 1023)
    TEMPERATURE_LIMIT = Register(31, 1, _RW, _E, 80, 0, 100)
    MAX_VOLTAGE_LIMIT = Register(32, 2, _RW, _E, 160, 95, 160)
    MIN_VOLTAGE_LIMIT = Register(34, 2, _RW, _E, 95, 95, 160)
    PWM_LIMIT = Register(36, 2, _RW, _E, 885, 0, 885)
    CURRENT_LIMIT = Register(38, 2, _RW, _E, 1193, 0, 1193)
    VELOCITY_LIMIT = Register(44, 4, _RW, _E, 330, 0, 1023)
    MAX_POSITION_LIMIT = Register(48, 4, _RW, _E, 4095, 0, 4095)
    MIN_POSITION_LIMIT = Register(52, 4, _RW, _E, 0, 0, 4095)
    STARTUP_CONFIGURATION = Register(60, 1, _RW, _E, 0, 0, 3)
    SHUTDOWN = Register(63, 1, _RW, _E, 52, 0, 255)
    TORQUE_ENABLE = Register(64, 1, _RW, _M, 0, 0, 1)
    LED = Register(65, 1, _RW, _M, 0, 0, 1)
    STATUS_RETURN_LEVEL = Register(68, 1, _RW, _M, 2, 0, 2)
    REGISTERED_INSTRUCTION = Register(69, 1, _R, _M, 0)
    HARDWARE_ERROR_STATUS = Register(70, 1, _R, _M, 0)
    VELOCITY_I_GAIN = Register(76, 2, _RW, _M, 1920, 0, 16383)
    VELOCITY_P_GAIN = Register(78, 2, _RW, _M, 100, 0, 16383)
    POSITION_D_GAIN = Register(80, 2, _RW, _M, 0, 0, 16383)
    POSITION_I_GAIN = Register(82, 2, _RW, _M, 0, 0, 16383)
    POSITION_P_GAIN = Register(84, 2, _RW, _M, 800, 0, 16383)
    FEEDFORWARD_2ND_GAIN = Register(88, 2, _RW, _M, 0, 0, 16383)
    FEEDFORWARD_1ST_GAIN = Register(90, 2, _RW, _M, 0, 0, 16383)
    BUS_WATCHDOG = Register(98, 1, _RW, _M, 0, 0, 127)
    GOAL_PWM = Register(100, 2, _RW, _M, 0, -885, 885, signed=True)
    GOAL_CURRENT = Register(102, 2, _RW, _M, 0, -1193, 1193, signed=True)
    GOAL_VELOCITY = Register(104, 4, _RW, _M, 0, -1023, 1023, signed=True)
    PROFILE_ACCELERATION = Register(108, 4, _RW, _M, 0, 0, 32767)
    PROFILE_VELOCITY = Register(112, 4, _RW, _M, 0, 0, 32767)
    GOAL_POSITION = Register(116, 4, _RW, _M, 0, -1048575, 1048575, signed=True)
    REALTIME_TICK = Register(120, 2, _R, _M, 0)
    MOVING = Register(122, 1, _R, _M, 0)
    MOVING_STATUS = Register(123, 1, _R, _M, 0)
    PRESENT_PWM = Register(124, 2, _R, _M, 0, signed=True)
    PRESENT_CURRENT = Register(126, 2, _R, _M, 0, signed=True)
    PRESENT_VELOCITY = Register(128, 4, _R, _M, 0, signed=True)
    PRESENT_POSITION = Register(132, 4, _R, _M, 0, signed=True)
    VELOCITY_TRAJECTORY = Register(136, 4, _R, _M, 0, signed=True)
    POSITION_TRAJECTORY = Register(140, 4, _R, _M, 0, signed=True)
    PRESENT_INPUT_VOLTAGE = Register(144, 2, _R, _M, 120)
    PRESENT_TEMPERATURE = Register(146, 1, _R, _M, 30)

    layout: tuple[int, int, bool]  # (address, size, signed), set below

    @property
    def address(self) -> int:
        return self.layout[0]

    @property
    def size(self) -> int:
        return self.layout[1]


# A plain attribute per member: Enum.value and Enum.__hash__ are Python-level calls, and the
# emulator reads these items tens of thousands of times a second.
for _reg in Reg:
    _reg.layout = (_reg.value.address, _reg.value.size, _reg.value.signed)


CONTROL_TABLE_SIZE = 147  # one past Present Temperature; the emulator rejects reads beyond it

# The per-tick state block: Moving 122 .. Present Temperature 146, 25 bytes. It starts four
# bytes before Present Current (126) so the Moving flag comes in the same read.
STATE_BLOCK_START = Reg.MOVING.address
STATE_BLOCK_SIZE = Reg.PRESENT_TEMPERATURE.address + 1 - STATE_BLOCK_START


class HardwareErrorFlag(enum.IntFlag):
    """Hardware Error Status (70) bits."""

    INPUT_VOLTAGE = 0x01
    OVERHEATING = 0x04
    MOTOR_ENCODER = 0x08
    ELECTRICAL_SHOCK = 0x10
    OVERLOAD = 0x20


@functools.lru_cache(maxsize=256)  # read for every servo on every tick: one byte, 256 answers
def hardware_error_names(bits: int) -> tuple[str, ...]:
    """Names of the Hardware Error Status bits set in `bits` (unknown bits as 'bit N')."""
    flags = HardwareErrorFlag.__members__.items()  # named pairs: a flag's .name is str | None
    names = [name.lower() for name, flag in flags if bits & flag.value]
    known = sum(flag.value for flag in HardwareErrorFlag)
    names += [f"bit {i}" for i in range(8) if bits & ~known & (1 << i)]
    return tuple(names)


def to_signed(raw: int, size: int) -> int:
    """Two's-complement decode of an unsigned `size`-byte register value."""
    bits = 8 * size
    raw &= (1 << bits) - 1
    return raw - (1 << bits) if raw >= 1 << (bits - 1) else raw


def to_unsigned(value: int, size: int) -> int:
    """Two's-complement encode of a signed value into `size` bytes (as an unsigned int)."""
    return value & ((1 << (8 * size)) - 1)


def decode(reg: Reg, data: bytes | bytearray, offset: int = 0) -> int:
    """The value of `reg` from little-endian bytes starting at `offset` (signed if the item is)."""
    _, size, signed = reg.layout
    return int.from_bytes(data[offset : offset + size], "little", signed=signed)


def encode(reg: Reg, value: int) -> bytes:
    """Little-endian bytes of `value` for `reg`; negative values in two's complement."""
    return to_unsigned(int(value), reg.size).to_bytes(reg.size, "little")


def velocity_to_rad_s(units: _Units) -> _Units:
    """Velocity register units (0.229 rpm) -> rad/s."""
    return units * RAD_S_PER_VELOCITY_UNIT


def rad_s_to_velocity(rad_s: float) -> int:
    """rad/s -> velocity register units (0.229 rpm), rounded to the nearest unit."""
    return round(rad_s / RAD_S_PER_VELOCITY_UNIT)


def current_to_ampere(units: _Units) -> _Units:
    """Current register units (2.69 mA) -> A."""
    return units * AMPERE_PER_CURRENT_UNIT


def ampere_to_current(ampere: float) -> int:
    """A -> current register units (2.69 mA), rounded."""
    return round(ampere / AMPERE_PER_CURRENT_UNIT)


PWM_FULL_SCALE = 885  # Present PWM / Goal PWM at full duty (e-manual: 0.113 % per unit)


def pwm_to_fraction(units: _Units) -> _Units:
    """PWM register units (-885..885) -> duty cycle as a fraction of full (-1..1)."""
    return units / PWM_FULL_SCALE


def voltage_to_volt(units: _Units) -> _Units:
    """Input voltage register units (0.1 V) -> V."""
    return units * VOLT_PER_VOLTAGE_UNIT


def acceleration_to_rad_s2(units: _Units) -> _Units:
    """Profile Acceleration units (214.577 rev/min^2) -> rad/s^2."""
    return units * RAD_S2_PER_ACCELERATION_UNIT


def rad_s2_to_acceleration(rad_s2: float) -> int:
    """rad/s^2 -> Profile Acceleration units (214.577 rev/min^2), rounded."""
    return round(rad_s2 / RAD_S2_PER_ACCELERATION_UNIT)


def profile_units(velocity_rad_s: float, acceleration_rad_s2: float) -> tuple[int, int]:
    """(Profile Velocity, Profile Acceleration) register units for a requested profile.

    velocity_rad_s [rad/s] and acceleration_rad_s2 [rad/s^2], each >= 0, are rounded to
    the nearest unit (0.229 rpm, 214.577 rev/min^2). The XM430 reads 0 as *unlimited*, so
    a positive request that rounds to 0 is written as 1, the smallest limited value: a
    gentle profile never becomes full speed. Only a request of exactly 0 gives 0. A
    value so raised is logged as a warning naming what is written instead.

    Raises ValueError for a negative or non-finite value, naming the field.
    """
    out = []
    for name, value, convert, convert_back in (
        ("velocity_rad_s", velocity_rad_s, rad_s_to_velocity, velocity_to_rad_s),
        (
            "acceleration_rad_s2",
            acceleration_rad_s2,
            rad_s2_to_acceleration,
            acceleration_to_rad_s2,
        ),
    ):
        if not math.isfinite(value) or value < 0:
            raise ValueError(f"profile {name} must be finite and >= 0 (0 = unlimited), got {value}")
        units = convert(value)
        if value > 0 and units == 0:
            units = 1
            _log.warning(
                "profile %s %.6g rounds to 0 units (unlimited): writing 1 unit (%.6g) instead",
                name,
                value,
                convert_back(1),
            )
        out.append(units)
    return out[0], out[1]


def register_at(address: int) -> Reg | None:
    """The register that starts at `address`, or None."""
    return _BY_ADDRESS.get(address)


_BY_ADDRESS = {reg.address: reg for reg in Reg}
_log = logging.getLogger(__name__)
