"""The emulated servo's control-table memory, with the access rules of the e-manual.

A write is checked whole before any byte changes (as the servo does): it must cover
complete items (Data Length Error), may not touch read-only or undefined addresses nor
EEPROM while torque is on (Access Error), must be inside each item's range (Data Range
Error) and inside the limits other items set (Data Limit Error).
"""

from __future__ import annotations

from hardware.dynamixel.control_table import (
    CONTROL_TABLE_SIZE,
    Access,
    Area,
    OperatingMode,
    Reg,
    decode,
)
from hardware.dynamixel.protocol import StatusError

_VALID_MODES = {int(mode) for mode in OperatingMode}
# The e-manual: Min/Max Position Limit bound Goal Position in Position Control Mode only
# (not in Extended Position nor Current-based Position Control Mode).
_POSITION_LIMITED_MODES = {OperatingMode.POSITION}
# Goal item -> (limit item, the goal must lie within +-limit or [min, max])
_LIMITS = {
    Reg.GOAL_PWM: Reg.PWM_LIMIT,
    Reg.GOAL_CURRENT: Reg.CURRENT_LIMIT,
    Reg.GOAL_VELOCITY: Reg.VELOCITY_LIMIT,
}


def _owner_map() -> list[Reg | None]:
    owners: list[Reg | None] = [None] * CONTROL_TABLE_SIZE
    for reg in Reg:
        for offset in range(reg.size):
            owners[reg.address + offset] = reg
    return owners


_OWNER = _owner_map()


class ServoMemory:
    """Bytes 0 .. CONTROL_TABLE_SIZE-1 of one XM430-W210, initialised to factory defaults."""

    def __init__(self, servo_id: int = 1) -> None:
        self.memory = bytearray(CONTROL_TABLE_SIZE)
        self.factory_reset(keep_id=False)
        self.set(Reg.ID, servo_id)

    def factory_reset(self, keep_id: bool = True, keep_baud: bool = False) -> None:
        """Every item back to its default, optionally keeping ID and Baud Rate."""
        kept = {reg: self.get(reg) for reg in (Reg.ID, Reg.BAUD_RATE)}
        for reg in Reg:
            self.set(reg, reg.value.default)
        if keep_id:
            self.set(Reg.ID, kept[Reg.ID])
        if keep_baud:
            self.set(Reg.BAUD_RATE, kept[Reg.BAUD_RATE])
        self.goals_to_limits()

    def reset_ram(self) -> None:
        """RAM items back to defaults, as a reboot does (EEPROM kept)."""
        for reg in Reg:
            if reg.value.area is Area.RAM:
                self.set(reg, reg.value.default)
        self.goals_to_limits()

    def goals_to_limits(self) -> None:
        """Goal PWM (100) := PWM Limit (36) and Goal Current (102) := Current Limit (38), as
        the firmware sets them at power-on, reboot and an Operating Mode change (e-manual:
        Goal PWM's initial value is the PWM Limit; the Operating Mode note resets Goal PWM
        to it; Goal Current is taken to follow its Current Limit alike)."""
        for goal, limit in _LIMITS.items():
            if goal is not Reg.GOAL_VELOCITY:
                self.set(goal, self.get(limit))

    def get(self, reg: Reg) -> int:
        """The value of `reg` (signed items decoded as signed)."""
        address, size, signed = reg.layout
        return int.from_bytes(self.memory[address : address + size], "little", signed=signed)

    def set(self, reg: Reg, value: int) -> None:
        """Store `value` without any check (the servo's own updates of R items)."""
        address, size, _ = reg.layout
        raw = int(value) & ((1 << (8 * size)) - 1)
        self.memory[address : address + size] = raw.to_bytes(size, "little")

    def read(self, address: int, length: int) -> tuple[StatusError, bytes]:
        """`length` bytes from `address`; gaps between items read as 0, as on the servo."""
        if length < 1 or address < 0 or address + length > CONTROL_TABLE_SIZE:
            return StatusError.ACCESS, b""
        return StatusError.NONE, bytes(self.memory[address : address + length])

    def write(self, address: int, data: bytes) -> StatusError:
        """Check and apply a write of `data` at `address`; the error number if refused."""
        regs, error = self._covered(address, len(data))
        if error is not StatusError.NONE:
            return error
        values = {reg: decode(reg, data, reg.address - address) for reg in regs}
        error = self._check(values)
        if error is StatusError.NONE:
            self.memory[address : address + len(data)] = data
        return error

    def _covered(self, address: int, length: int) -> tuple[list[Reg], StatusError]:
        if length < 1 or address < 0 or address + length > CONTROL_TABLE_SIZE:
            return [], StatusError.ACCESS
        regs: list[Reg] = []
        for offset in range(address, address + length):
            reg = _OWNER[offset]
            if reg is None or reg.value.access is not Access.RW:
                return [], StatusError.ACCESS
            if reg.address < address or reg.address + reg.size > address + length:
                return [], StatusError.DATA_LENGTH
            if not regs or regs[-1] is not reg:
                regs.append(reg)
        torque_on = self.get(Reg.TORQUE_ENABLE) == 1
        if torque_on and any(reg.value.area is Area.EEPROM for reg in regs):
            return [], StatusError.ACCESS
        return regs, StatusError.NONE

    def _check(self, values: dict[Reg, int]) -> StatusError:
        for reg, value in values.items():
            if not reg.value.low <= value <= reg.value.high:
                return StatusError.DATA_RANGE
            if reg is Reg.OPERATING_MODE and value not in _VALID_MODES:
                return StatusError.DATA_RANGE
        for reg, value in values.items():
            if self._over_limit(reg, value, values):
                return StatusError.DATA_LIMIT
        return StatusError.NONE

    def _over_limit(self, reg: Reg, value: int, pending: dict[Reg, int]) -> bool:
        def current(item: Reg) -> int:
            return pending.get(item, self.get(item))

        if reg in _LIMITS:
            return abs(value) > current(_LIMITS[reg])
        if reg is Reg.GOAL_POSITION and current(Reg.OPERATING_MODE) in _POSITION_LIMITED_MODES:
            return not current(Reg.MIN_POSITION_LIMIT) <= value <= current(Reg.MAX_POSITION_LIMIT)
        return False
