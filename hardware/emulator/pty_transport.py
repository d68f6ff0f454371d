"""An XM430-W210 bus emulator on a pseudo-terminal, speaking Dynamixel Protocol 2.0.

`ServoEmulator` is the transport: it opens a pty pair, reads bytes on the master side from
a background thread, hands them to an `EmulatedBus` (hardware/emulator/emulated_bus.py),
which answers them, and writes the reply packets back. Any Dynamixel client
(dynamixel-sdk's PortHandler, the ROBOTIS Wizard via a symlink, our DynamixelBus) opens
`emulator.port` (the slave, e.g. /dev/pts/3) at any standard baud rate (a pty has no line
rate; Baud Rate writes are stored and otherwise ignored). Faults are injected per servo
through `inject` (see hardware.emulator.emulated_servo.Faults).
"""

from __future__ import annotations

import contextlib
import os
import select
import threading
import time
import tty
from collections.abc import Callable, Iterable

from hardware.dynamixel.protocol import Packet
from hardware.emulator.emulated_bus import EmulatedBus, Outgoing
from hardware.emulator.emulated_servo import EmulatedServo
from hardware.shaft_motion import MotionModel


class ServoEmulator:
    """Emulated servos with `ids` on one pty; use as a context manager or start()/stop().

    The bus (`self.bus`) is only touched under `self.lock`; hold it to change servos'
    tables from another thread while the emulator runs.
    """

    def __init__(
        self,
        ids: Iterable[int] = (1, 2, 3),
        model: MotionModel | None = None,
        initial_ticks: int = 2048,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        """``clock`` [s]: what the servos' motion is stepped by between packets (a
        simulated one moves them in simulated time; a Reboot's boot still takes wall
        time, as the bus master waits it out)."""
        boot = None if clock is time.monotonic else time.monotonic
        self.bus = EmulatedBus(ids, model, initial_ticks, clock, boot)
        self.lock = threading.RLock()
        self.unread_replies = 0
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo, no line editing: bytes pass as sent
        # Never block on a client that stopped reading: a real bus does not wait either.
        os.set_blocking(self._master, False)
        self.port = os.ttyname(self._slave)
        self._wake_r, self._wake_w = os.pipe()
        self._running = False
        self._thread: threading.Thread | None = None

    # -- the bus, as tests and demos see it ----------------------------------------------
    @property
    def servos(self) -> list[EmulatedServo]:
        return self.bus.servos

    @property
    def model(self) -> MotionModel:
        return self.bus.model

    @property
    def packets_received(self) -> int:
        return self.bus.packets_received

    @property
    def crc_errors(self) -> int:
        return self.bus.crc_errors

    @property
    def internal_errors(self) -> int:
        return self.bus.internal_errors

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
            return self.bus.servo(servo_id)

    def inject(self, servo_id: int, **faults: object) -> None:
        """Set fault fields (see Faults) on a servo, e.g. inject(2, drop_replies=3)."""
        with self.lock:
            self.bus.inject(servo_id, **faults)

    def clear_faults(self) -> None:
        """Remove every injected fault (latched hardware errors stay: reboot clears those)."""
        with self.lock:
            self.bus.clear_faults()

    def raise_hardware_error(self, servo_id: int, bits: int) -> None:
        """Latch Hardware Error Status bits on a servo (see control_table.HardwareErrorFlag)."""
        with self.lock:
            self.bus.servo(servo_id).raise_hardware_error(bits)

    def place(self, ticks: dict[int, int]) -> None:
        """Put shafts at rest at raw positions [ticks] (e.g. the homing pose), by servo id."""
        with self.lock:
            self.bus.place(ticks)

    def handle(self, packet: Packet) -> None:
        """Answer one instruction packet on the pty as the bus of servos would."""
        with self.lock:
            self._write(self.bus.handle(packet))

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
            with self.lock:
                self._write(self.bus.feed(data))

    def _write(self, out: list[Outgoing]) -> None:
        """Put status packets on the wire, each after its servo's delay."""
        for packet, delay_s in out:
            if delay_s > 0:
                time.sleep(delay_s)
            try:
                os.write(self._master, packet)
            except BlockingIOError:  # nobody reads the pty and its buffer is full: bytes lost
                self.unread_replies += 1
