"""One emulated XM430-W210: its control table, registered instruction and injected faults.

The servo answers the instructions addressed to it alone (ping, read, write, reg write,
action, factory reset, reboot, clear) with a status packet's parameters and error number;
framing, broadcast and group instructions are the bus's (hardware/emulator/emulated_bus.py).

Present Position = shaft + Homing Offset - a whole number of turns (`turn_ticks`): like the
servo, the count runs on across the encoder's seam while powered and restarts at one turn
(shaft 0 .. 4095) when torque comes on in Position Control Mode, when the Operating Mode
changes and at reboot; Position Control Mode ignores a Homing Offset outside -1024 .. 1024
(hardware/seam.py).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from hardware.bus import OperatingMode
from hardware.dynamixel.control_table import Reg
from hardware.dynamixel.protocol import ALERT_BIT, Instruction, StatusError
from hardware.emulator.memory import ServoMemory
from hardware.encoder import TICKS_PER_REV
from hardware.seam import effective_homing_offset

_READ_INSTRUCTIONS = {
    Instruction.READ,
    Instruction.SYNC_READ,
    Instruction.FAST_SYNC_READ,
    Instruction.BULK_READ,
    Instruction.FAST_BULK_READ,
}
_CLEAR_MULTI_TURN = bytes([0x01, 0x44, 0x58, 0x4C, 0x22])


@dataclass
class Faults:
    """Faults injected into one servo (mutable; the emulator reads them under its lock).

    drop_replies / corrupt_replies / wrong_id_replies: how many of the next status packets
    to swallow, send with a broken CRC, or send from another id; duplicate_replies: how
    many to send twice; late_replies: how many to hold back until the bus gets its next
    instruction packet, then send first (a reply so late that it meets the next request,
    whatever the client's timeout); reorder_replies: how many to hold back until the bus
    has sent its next status packet (out of order: in a sync read, after the next servo's).
    delay_s: extra delay [s] before every reply; boot_s: how long [s] the servo is deaf
    after a Reboot (the real one restarts its firmware); unplugged: the servo neither
    hears nor answers anything; ignore_requests: how many of the next instruction packets
    addressed to this servo alone it does not hear (noise at its receiver).
    """

    drop_replies: int = 0
    corrupt_replies: int = 0
    wrong_id_replies: int = 0
    duplicate_replies: int = 0
    late_replies: int = 0
    reorder_replies: int = 0
    delay_s: float = 0.0
    boot_s: float = 0.0
    unplugged: bool = False
    ignore_requests: int = 0


@dataclass(frozen=True)
class Reply:
    """A status to send: error number and parameters (the alert bit is added on sending)."""

    error: StatusError
    params: bytes = b""


class EmulatedServo:
    """Control table plus the per-servo state that lives outside it."""

    def __init__(self, servo_id: int) -> None:
        self.table = ServoMemory(servo_id)
        self.faults = Faults()
        self.registered: tuple[int, bytes] | None = None
        self.reboots = 0
        self.turn_ticks = 0  # whole turns [ticks] the count is behind the shaft
        self.deaf_until = float("-inf")  # the bus clock's time a Reboot's boot ends
        # ((command bytes, turn_ticks), MotionCommand) of hardware.emulator.stepping, so
        # unchanged tables are not decoded again on every packet.
        self.command_cache: tuple[tuple[bytes, int], object] | None = None

    @property
    def servo_id(self) -> int:
        return self.table.get(Reg.ID)

    @property
    def return_delay_s(self) -> float:
        """Return Delay Time (9) in seconds (2 us per unit)."""
        return self.table.get(Reg.RETURN_DELAY_TIME) * 2e-6

    def error_byte(self, error: StatusError) -> int:
        """The status packet's error byte: the error number plus the alert bit if faulted."""
        alert = ALERT_BIT if self.table.get(Reg.HARDWARE_ERROR_STATUS) else 0
        return int(error) | alert

    def answers(self, instruction: int) -> bool:
        """Whether Status Return Level (68) lets this instruction get a status packet."""
        level = self.table.get(Reg.STATUS_RETURN_LEVEL)
        if instruction == Instruction.PING:
            return True
        if instruction in _READ_INSTRUCTIONS:
            return level >= 1
        return level >= 2

    def raise_hardware_error(self, bits: int) -> None:
        """Latch Hardware Error Status bits and drop torque, as the servo's shutdown does."""
        status = self.table.get(Reg.HARDWARE_ERROR_STATUS) | bits
        self.table.set(Reg.HARDWARE_ERROR_STATUS, status)
        if self.shut_down:
            self.table.set(Reg.TORQUE_ENABLE, 0)

    @property
    def shut_down(self) -> bool:
        """A latched hardware error is one the Shutdown (63) item turns torque off for."""
        return bool(self.table.get(Reg.HARDWARE_ERROR_STATUS) & self.table.get(Reg.SHUTDOWN))

    @property
    def present_offset(self) -> int:
        """Present Position - shaft position [ticks]: the Homing Offset in force less the
        turns the count has restarted by."""
        t = self.table
        offset = effective_homing_offset(t.get(Reg.OPERATING_MODE), t.get(Reg.HOMING_OFFSET))
        return offset - self.turn_ticks

    def restart_count(self) -> None:
        """Count from the shaft's one-turn position again (Present Position then lies in
        H .. 4095 + H), as the servo does at torque-on in Position Control Mode, on a mode
        change and at power-on."""
        shaft = self.table.get(Reg.PRESENT_POSITION) - self.present_offset
        self.turn_ticks = shaft // TICKS_PER_REV * TICKS_PER_REV
        self.table.set(Reg.PRESENT_POSITION, shaft + self.present_offset)

    def write(self, address: int, data: bytes) -> StatusError:
        """A checked write; torque stays off while a shutdown hardware error is latched."""
        t = self.table
        before = (t.get(Reg.TORQUE_ENABLE), t.get(Reg.OPERATING_MODE), self.present_offset)
        error = t.write(address, data)
        if error is StatusError.NONE and self.shut_down:
            t.set(Reg.TORQUE_ENABLE, 0)
        if error is StatusError.NONE:
            self._after_write(*before)
        return error

    def _after_write(self, torque: int, mode: int, offset: int) -> None:
        t = self.table
        # a new Homing Offset shifts Present Position at once (stepping keeps it so)
        shaft = t.get(Reg.PRESENT_POSITION) - offset
        t.set(Reg.PRESENT_POSITION, shaft + self.present_offset)
        torque_on = not torque and t.get(Reg.TORQUE_ENABLE)
        in_position = t.get(Reg.OPERATING_MODE) == OperatingMode.POSITION
        if t.get(Reg.OPERATING_MODE) != mode:
            t.goals_to_limits()  # the firmware resets Goal PWM and Goal Current to limits
        if t.get(Reg.OPERATING_MODE) != mode or (torque_on and in_position):
            self.restart_count()

    def handle(self, instruction: int, params: bytes) -> Reply:
        """Execute a unicast instruction (after-effects of reboot/reset: see `finish`)."""
        handler = _HANDLERS.get(instruction)
        if handler is None:
            return Reply(StatusError.INSTRUCTION)
        return handler(self, params)

    def finish(self, instruction: int, params: bytes) -> None:
        """Effects the servo applies after its status packet has gone out."""
        if instruction == Instruction.REBOOT:
            self.restart_count()  # from Present Position, before the RAM is cleared
            self.table.reset_ram()
            self.registered = None
            self.reboots += 1
        elif instruction == Instruction.FACTORY_RESET and params:
            offset = self.present_offset
            self.table.factory_reset(keep_id=params[0] != 0xFF, keep_baud=params[0] == 0x02)
            self.registered = None
            self._after_write(0, -1, offset)

    def _ping(self, params: bytes) -> Reply:
        model = self.table.get(Reg.MODEL_NUMBER).to_bytes(2, "little")
        return Reply(StatusError.NONE, model + bytes([self.table.get(Reg.FIRMWARE_VERSION)]))

    def _read(self, params: bytes) -> Reply:
        if len(params) != 4:
            return Reply(StatusError.DATA_LENGTH)
        address = int.from_bytes(params[0:2], "little")
        length = int.from_bytes(params[2:4], "little")
        error, data = self.table.read(address, length)
        return Reply(error, data)

    def _write(self, params: bytes) -> Reply:
        if len(params) < 3:
            return Reply(StatusError.DATA_LENGTH)
        return Reply(self.write(int.from_bytes(params[0:2], "little"), params[2:]))

    def _reg_write(self, params: bytes) -> Reply:
        if len(params) < 3:
            return Reply(StatusError.DATA_LENGTH)
        self.registered = (int.from_bytes(params[0:2], "little"), params[2:])
        self.table.set(Reg.REGISTERED_INSTRUCTION, 1)
        return Reply(StatusError.NONE)

    def action(self) -> Reply:
        """Apply the registered write; an Instruction Error if none is registered."""
        if self.registered is None:
            return Reply(StatusError.INSTRUCTION)
        address, data = self.registered
        self.registered = None
        self.table.set(Reg.REGISTERED_INSTRUCTION, 0)
        return Reply(self.write(address, data))

    def _action(self, params: bytes) -> Reply:
        return self.action()

    def _factory_reset(self, params: bytes) -> Reply:
        if len(params) != 1:
            return Reply(StatusError.DATA_LENGTH)
        if params[0] not in (0x01, 0x02, 0xFF):
            return Reply(StatusError.DATA_RANGE)
        return Reply(StatusError.NONE)

    def _reboot(self, params: bytes) -> Reply:
        return Reply(StatusError.NONE)

    def _clear(self, params: bytes) -> Reply:
        # Position mode keeps no turn count, so clearing multi-turn changes nothing here.
        ok = params == _CLEAR_MULTI_TURN
        return Reply(StatusError.NONE if ok else StatusError.DATA_RANGE)


# Keyed by the wire's instruction byte: Instruction members hash and compare as their ints.
_HANDLERS: dict[int, Callable[[EmulatedServo, bytes], Reply]] = {
    Instruction.PING: EmulatedServo._ping,
    Instruction.READ: EmulatedServo._read,
    Instruction.WRITE: EmulatedServo._write,
    Instruction.REG_WRITE: EmulatedServo._reg_write,
    Instruction.ACTION: EmulatedServo._action,
    Instruction.FACTORY_RESET: EmulatedServo._factory_reset,
    Instruction.REBOOT: EmulatedServo._reboot,
    Instruction.CLEAR: EmulatedServo._clear,
}
