"""The emulated bus: a request packet in, the reply packets the servos would send out.

No pty and no thread: `EmulatedBus.handle` takes one decoded instruction packet and returns
the status packets, in wire order, each with the delay its servo waits before sending
(Return Delay Time plus any injected delay), led by any status packets an injected fault
held back from an earlier request (late replies). `feed` does the same from raw bytes. The pty
transport (hardware/emulator/pty_transport.py) puts these on the wire; a test can call them
directly. Servo motion comes from a pluggable hardware.shaft_motion.MotionModel,
stepped by the clock's time between packets.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterable
from typing import NamedTuple

from hardware.dynamixel.control_table import RAD_PER_TICK, Reg
from hardware.dynamixel.protocol import (
    BROADCAST_ID,
    Instruction,
    Packet,
    PacketReader,
    StatusError,
    frame,
    status_packet,
    unstuff,
)
from hardware.emulator.emulated_servo import EmulatedServo, Faults, Reply
from hardware.emulator.group_instructions import handle_group
from hardware.emulator.stepping import advance_servos
from hardware.shaft_motion import MotionModel, SimpleServoModel

_log = logging.getLogger(__name__)

_GROUP = {
    Instruction.SYNC_READ,
    Instruction.SYNC_WRITE,
    Instruction.FAST_SYNC_READ,
    Instruction.BULK_READ,
    Instruction.BULK_WRITE,
    Instruction.FAST_BULK_READ,
}


class Outgoing(NamedTuple):
    """One status packet for the wire, sent after its servo's delay [s]."""

    packet: bytes
    delay_s: float


class EmulatedBus:
    """Emulated XM430-W210 servos with `ids` on one bus, answering instruction packets."""

    def __init__(
        self,
        ids: Iterable[int] = (1, 2, 3),
        model: MotionModel | None = None,
        initial_ticks: int = 2048,
        clock: Callable[[], float] = time.monotonic,
        boot_clock: Callable[[], float] | None = None,
    ) -> None:
        """``clock`` [s] steps the servos' motion between packets; ``boot_clock`` [s] (the
        same by default) times a Reboot's boot, which the bus master waits out in its own
        time (a loop on simulated time blocks in the tick that reboots, so its clock
        stands still meanwhile: give it the wall clock)."""
        self.servos = [EmulatedServo(servo_id) for servo_id in ids]
        if len({s.servo_id for s in self.servos}) != len(self.servos):
            raise ValueError("servo ids must be distinct")
        self.model: MotionModel = model or SimpleServoModel()
        self.clock = clock
        self.boot_clock = boot_clock or clock
        self.packets_received = 0
        self.crc_errors = 0
        self.internal_errors = 0
        self._reader = PacketReader()
        self._late: list[Outgoing] = []  # held by late_replies until the next request
        self._reordered: list[Outgoing] = []  # held by reorder_replies until the next reply
        self._last_step = clock()
        self._reset_model({s.servo_id: initial_ticks for s in self.servos})

    # -- test and demo hooks -----------------------------------------------------------
    def servo(self, servo_id: int) -> EmulatedServo:
        """The servo that currently has `servo_id` (KeyError if none)."""
        for servo in self.servos:
            if servo.servo_id == servo_id:
                return servo
        raise KeyError(f"no emulated servo with id {servo_id}")

    def inject(self, servo_id: int, **faults: object) -> None:
        """Set fault fields (see Faults) on a servo, e.g. inject(2, drop_replies=3)."""
        target = self.servo(servo_id).faults
        for name, value in faults.items():
            if not hasattr(target, name):
                raise AttributeError(f"no fault named {name!r}")
            setattr(target, name, value)

    def clear_faults(self) -> None:
        """Remove every injected fault (latched hardware errors stay: reboot clears those;
        replies already held back by late_replies or reorder_replies still go out)."""
        for servo in self.servos:
            servo.faults = Faults()

    def place(self, ticks: dict[int, int]) -> None:
        """Put shafts at rest at raw positions [ticks] (e.g. the homing pose), by servo id."""
        self._advance()
        self._reset_model(ticks)

    def _reset_model(self, ticks: dict[int, int]) -> None:
        present = [s.table.get(Reg.PRESENT_POSITION) for s in self.servos]
        for i, servo in enumerate(self.servos):
            present[i] = ticks.get(servo.servo_id, present[i])
            servo.table.set(Reg.PRESENT_POSITION, present[i])
            servo.table.set(Reg.GOAL_POSITION, present[i])
        offsets = [s.present_offset for s in self.servos]
        self.model.reset([(p - o) * RAD_PER_TICK for p, o in zip(present, offsets, strict=True)])
        self._last_step = self.clock()

    # -- answering ---------------------------------------------------------------------
    def feed(self, data: bytes) -> list[Outgoing]:
        """Answer every packet completed by `data` (bytes as they came off the wire)."""
        out: list[Outgoing] = []
        for packet in self._reader.feed(data):
            try:
                out += self.handle(packet)
            except Exception:  # a bug must cost one packet, not the whole bus
                self.internal_errors += 1
                _log.exception("emulator failed on %r", packet)
        return out

    def handle(self, packet: Packet) -> list[Outgoing]:
        """Answer one instruction packet as the bus of servos would, in wire order; status
        packets held back from earlier requests by late_replies go out first."""
        late, self._late = self._late, []
        return late + self._answer(packet)

    def _answer(self, packet: Packet) -> list[Outgoing]:
        self.packets_received += 1
        self._advance()
        if not packet.crc_ok:
            self.crc_errors += 1
            target = self._listening(packet.packet_id)
            if target is None:
                return []
            return self._send(self._replies(target, packet.instruction, Reply(StatusError.CRC)))
        if packet.packet_id == BROADCAST_ID:
            return self._send(self._broadcast(packet))
        servo = self._listening(packet.packet_id)
        if servo is None:
            return []
        if servo.faults.ignore_requests > 0:
            servo.faults.ignore_requests -= 1
            return []
        # The status goes out under the id and Status Return Level the packet arrived under,
        # so a write that changes either still gets its answer.
        servo_id, answers = servo.servo_id, servo.answers(packet.instruction)
        reply = servo.handle(packet.instruction, packet.params)
        error = servo.error_byte(reply.error)
        out = self._send([(servo, status_packet(servo_id, error, reply.params))] if answers else [])
        self._finish(servo, packet)
        return out

    def _broadcast(self, packet: Packet) -> list[tuple[EmulatedServo, bytes]]:
        if packet.instruction in _GROUP:
            return handle_group(self._listening, packet)
        if packet.instruction == Instruction.PING:
            sent: list[tuple[EmulatedServo, bytes]] = []
            for servo in sorted(self._alive(), key=lambda s: s.servo_id):
                sent += self._replies(servo, Instruction.PING, servo.handle(Instruction.PING, b""))
            return sent
        # write, reg write, action, reboot, factory reset: every servo acts, none answer
        for servo in self._alive():
            servo.handle(packet.instruction, packet.params)
            self._finish(servo, packet)
        return []

    def _finish(self, servo: EmulatedServo, packet: Packet) -> None:
        """The servo's after-effects; a Reboot leaves it deaf for its boot time."""
        servo.finish(packet.instruction, packet.params)
        if packet.instruction == Instruction.REBOOT:
            servo.deaf_until = self.boot_clock() + servo.faults.boot_s

    def _alive(self) -> list[EmulatedServo]:
        """The servos that hear the bus now: plugged in and not booting."""
        now = self.boot_clock()
        return [s for s in self.servos if not s.faults.unplugged and now >= s.deaf_until]

    def _listening(self, servo_id: int) -> EmulatedServo | None:
        for servo in self._alive():
            if servo.servo_id == servo_id:
                return servo
        return None

    @staticmethod
    def _replies(
        servo: EmulatedServo, instruction: int, reply: Reply
    ) -> list[tuple[EmulatedServo, bytes]]:
        if not servo.answers(instruction):
            return []
        return [(servo, status_packet(servo.servo_id, servo.error_byte(reply.error), reply.params))]

    def _send(self, sent: list[tuple[EmulatedServo, bytes]]) -> list[Outgoing]:
        """Each servo's status packet through that servo's faults (some are swallowed,
        some sent twice, some held back for later)."""
        out: list[Outgoing] = []
        for servo, packet in sent:
            faults = servo.faults
            faulted = _through_faults(faults, packet)
            if faulted is None:
                continue
            outgoing = Outgoing(faulted, servo.return_delay_s + faults.delay_s)
            copies = [outgoing]
            if faults.duplicate_replies > 0:
                faults.duplicate_replies -= 1
                copies.append(Outgoing(faulted, 0.0))
            if faults.late_replies > 0:
                faults.late_replies -= 1
                self._late += copies
            elif faults.reorder_replies > 0:
                faults.reorder_replies -= 1
                self._reordered += copies
            else:
                reordered, self._reordered = self._reordered, []
                out += copies + reordered
        return out

    def _advance(self) -> None:
        now = self.clock()
        advance_servos(self.model, self.servos, now - self._last_step, now)
        self._last_step = now


def _through_faults(faults: Faults, packet: bytes) -> bytes | None:
    """The packet as the injected faults let it out (None: dropped); counts them down."""
    if faults.drop_replies > 0:
        faults.drop_replies -= 1
        return None
    if faults.wrong_id_replies > 0:
        faults.wrong_id_replies -= 1
        packet = frame((packet[4] + 1) % 0xFD, unstuff(packet[7:-2]))
    if faults.corrupt_replies > 0:
        faults.corrupt_replies -= 1
        packet = packet[:-1] + bytes([packet[-1] ^ 0xFF])
    return packet
