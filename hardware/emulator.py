"""An XM430-W210 bus emulator on a pseudo-terminal, speaking Dynamixel Protocol 2.0.

`ServoEmulator` opens a pty pair and answers on the master side from a background thread;
any Dynamixel client (dynamixel-sdk's PortHandler, the ROBOTIS Wizard via a symlink, our
DynamixelBus) opens `emulator.port` (the slave, e.g. /dev/pts/3) at any standard baud rate
(a pty has no line rate; Baud Rate writes are stored and otherwise ignored). Servo motion
comes from a pluggable hardware.motion.MotionModel, stepped by the wall time between
packets. Faults are injected per servo through `inject` (see emulated_servo.Faults).
"""

from __future__ import annotations

import contextlib
import logging
import os
import select
import threading
import time
import tty
from collections.abc import Iterable

from hardware import emulator_groups
from hardware.dynamixel.control_table import RAD_PER_TICK, Reg
from hardware.dynamixel.protocol import (
    BROADCAST_ID,
    Instruction,
    Packet,
    PacketReader,
    StatusError,
    frame,
    unstuff,
)
from hardware.dynamixel.protocol import status_packet as _status_packet
from hardware.emulated_servo import EmulatedServo, Faults, Reply
from hardware.motion import MotionModel, SimpleServoModel
from hardware.servo_dynamics import advance_servos

_log = logging.getLogger(__name__)

_GROUP = {
    Instruction.SYNC_READ,
    Instruction.SYNC_WRITE,
    Instruction.FAST_SYNC_READ,
    Instruction.BULK_READ,
    Instruction.BULK_WRITE,
    Instruction.FAST_BULK_READ,
}


class ServoEmulator:
    """Emulated servos with `ids` on one pty; use as a context manager or start()/stop()."""

    def __init__(
        self,
        ids: Iterable[int] = (1, 2, 3),
        model: MotionModel | None = None,
        initial_ticks: int = 2048,
    ) -> None:
        self.servos = [EmulatedServo(servo_id) for servo_id in ids]
        if len({s.servo_id for s in self.servos}) != len(self.servos):
            raise ValueError("servo ids must be distinct")
        self.model: MotionModel = model or SimpleServoModel()
        self.lock = threading.RLock()
        self.packets_received = 0
        self.crc_errors = 0
        self.internal_errors = 0
        self.unread_replies = 0
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo, no line editing: bytes pass as sent
        # Never block on a client that stopped reading: a real bus does not wait either.
        os.set_blocking(self._master, False)
        self.port = os.ttyname(self._slave)
        self._wake_r, self._wake_w = os.pipe()
        self._running = False
        self._thread: threading.Thread | None = None
        self._reader = PacketReader()
        self._last_step = time.monotonic()
        self._reset_model({s.servo_id: initial_ticks for s in self.servos})

    # -- lifecycle ---------------------------------------------------------------------
    def start(self) -> ServoEmulator:
        """Start answering on the pty (idempotent)."""
        if not self._running:
            self._running = True
            self._thread = threading.Thread(target=self._serve, name="servo-emulator", daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread and close the pty; the emulator cannot be restarted."""
        if self._thread is not None:
            self._running = False
            os.write(self._wake_w, b"x")
            self._thread.join(timeout=5.0)
            self._thread = None
        for fd in (self._master, self._slave, self._wake_r, self._wake_w):
            with contextlib.suppress(OSError):
                os.close(fd)
        self._master = self._slave = self._wake_r = self._wake_w = -1

    def __enter__(self) -> ServoEmulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- test and demo hooks -----------------------------------------------------------
    def servo(self, servo_id: int) -> EmulatedServo:
        """The servo that currently has `servo_id` (KeyError if none).

        Takes the lock, so after a status packet has arrived the servo's after-effects
        (reboot, factory reset) are complete when this returns.
        """
        with self.lock:
            for servo in self.servos:
                if servo.servo_id == servo_id:
                    return servo
        raise KeyError(f"no emulated servo with id {servo_id}")

    def inject(self, servo_id: int, **faults: object) -> None:
        """Set fault fields (see Faults) on a servo, e.g. inject(2, drop_replies=3)."""
        with self.lock:
            target = self.servo(servo_id).faults
            for name, value in faults.items():
                if not hasattr(target, name):
                    raise AttributeError(f"no fault named {name!r}")
                setattr(target, name, value)

    def clear_faults(self) -> None:
        """Remove every injected fault (latched hardware errors stay: reboot clears those)."""
        with self.lock:
            for servo in self.servos:
                servo.faults = Faults()

    def raise_hardware_error(self, servo_id: int, bits: int) -> None:
        """Latch Hardware Error Status bits on a servo (see registers.HardwareErrorFlag)."""
        with self.lock:
            self.servo(servo_id).raise_hardware_error(bits)

    def place(self, ticks: dict[int, int]) -> None:
        """Put shafts at rest at raw positions [ticks] (e.g. the homing pose), by servo id."""
        with self.lock:
            self._advance()
            self._reset_model(ticks)

    def _reset_model(self, ticks: dict[int, int]) -> None:
        present = [s.table.get(Reg.PRESENT_POSITION) for s in self.servos]
        for i, servo in enumerate(self.servos):
            present[i] = ticks.get(servo.servo_id, present[i])
            servo.table.set(Reg.PRESENT_POSITION, present[i])
            servo.table.set(Reg.GOAL_POSITION, present[i])
        offsets = [s.table.get(Reg.HOMING_OFFSET) for s in self.servos]
        self.model.reset([(p - o) * RAD_PER_TICK for p, o in zip(present, offsets, strict=True)])
        self._last_step = time.monotonic()

    # -- serving -----------------------------------------------------------------------
    def _serve(self) -> None:
        while self._running:
            ready, _, _ = select.select([self._master, self._wake_r], [], [], 0.5)
            if self._wake_r in ready or not self._running:
                return
            if self._master not in ready:
                continue
            try:
                data = os.read(self._master, 4096)
            except OSError:  # EIO while no client has the slave open: just wait
                time.sleep(0.01)
                continue
            for packet in self._reader.feed(data):
                with self.lock:
                    try:
                        self.handle(packet)
                    except Exception:  # a bug must cost one packet, not the whole bus
                        self.internal_errors += 1
                        _log.exception("emulator failed on %r", packet)

    def handle(self, packet: Packet) -> None:
        """Answer one instruction packet as the bus of servos would."""
        self.packets_received += 1
        self._advance()
        if not packet.crc_ok:
            self.crc_errors += 1
            target = self._listening(packet.packet_id)
            if target is not None:
                self._reply(target, packet.instruction, Reply(StatusError.CRC))
            return
        if packet.packet_id == BROADCAST_ID:
            self._broadcast(packet)
            return
        servo = self._listening(packet.packet_id)
        if servo is None:
            return
        # The status goes out under the id and Status Return Level the packet arrived under,
        # so a write that changes either still gets its answer.
        servo_id, answers = servo.servo_id, servo.answers(packet.instruction)
        reply = servo.handle(packet.instruction, packet.params)
        if answers:
            error = servo.error_byte(reply.error)
            self.send(servo, _status_packet(servo_id, error, reply.params))
        servo.finish(packet.instruction, packet.params)

    def _broadcast(self, packet: Packet) -> None:
        if packet.instruction in _GROUP:
            emulator_groups.handle_group(self, packet)
        elif packet.instruction == Instruction.PING:
            for servo in sorted(self._alive(), key=lambda s: s.servo_id):
                self._reply(servo, Instruction.PING, servo.handle(Instruction.PING, b""))
        else:  # write, reg write, action, reboot, factory reset: every servo acts, none answer
            for servo in self._alive():
                servo.handle(packet.instruction, packet.params)
                servo.finish(packet.instruction, packet.params)

    def _alive(self) -> list[EmulatedServo]:
        return [s for s in self.servos if not s.faults.unplugged]

    def _listening(self, servo_id: int) -> EmulatedServo | None:
        for servo in self._alive():
            if servo.servo_id == servo_id:
                return servo
        return None

    def _reply(self, servo: EmulatedServo, instruction: int, reply: Reply) -> None:
        if servo.answers(instruction):
            packet = _status_packet(servo.servo_id, servo.error_byte(reply.error), reply.params)
            self.send(servo, packet)

    def send(self, servo: EmulatedServo, packet: bytes) -> None:
        """Put one servo's status packet on the wire, through that servo's faults."""
        faults = servo.faults
        if faults.drop_replies > 0:
            faults.drop_replies -= 1
            return
        if faults.wrong_id_replies > 0:
            faults.wrong_id_replies -= 1
            packet = frame((packet[4] + 1) % 0xFD, unstuff(packet[7:-2]))
        if faults.corrupt_replies > 0:
            faults.corrupt_replies -= 1
            packet = packet[:-1] + bytes([packet[-1] ^ 0xFF])
        delay = servo.return_delay_s + faults.delay_s
        if delay > 0:
            time.sleep(delay)
        try:
            os.write(self._master, packet)
        except BlockingIOError:  # nobody reads the pty and its buffer is full: bytes lost
            self.unread_replies += 1

    def _advance(self) -> None:
        now = time.monotonic()
        advance_servos(self.model, self.servos, now - self._last_step, now)
        self._last_step = now

