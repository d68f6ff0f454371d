"""The emulated XM430-W210 bus as tests use it: servo ids, a baud rate, a fast emulator,
a DynamixelBus config for it, and a raw pty client that speaks bytes without the SDK."""

from __future__ import annotations

import os
import select
import time
import tty

from hardware.calibration import JointCalibration
from hardware.dynamixel.control_table import Reg
from hardware.dynamixel.driver import DynamixelConfig
from hardware.emulator import ServoEmulator

IDS = (1, 2, 3)
BAUD = 1_000_000  # a standard rate: pyserial sets it on a pty with plain termios


def fast(emulator: ServoEmulator) -> ServoEmulator:
    """Return Delay Time 0 on every servo (factory 250 = 500 us), as a tuned robot has."""
    with emulator.lock:
        for servo in emulator.servos:
            servo.table.set(Reg.RETURN_DELAY_TIME, 0)
    return emulator


def make_config(port: str, **overrides: object) -> DynamixelConfig:
    joints = tuple(JointCalibration(servo_id) for servo_id in IDS)
    settings = {"joints": joints, "port": port, "baudrate": BAUD, **overrides}
    return DynamixelConfig(**settings)  # type: ignore[arg-type]


class RawPort:
    """The client end of the pty without any SDK: bytes in, bytes out."""

    def __init__(self, path: str) -> None:
        self.fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
        tty.setraw(self.fd)

    def exchange(self, packet: bytes, expect: int, timeout_s: float = 1.0) -> bytes:
        """Send `packet`, then read until `expect` bytes arrived or `timeout_s` passed."""
        self.write(packet)
        return self.read(expect, timeout_s)

    def write(self, packet: bytes) -> None:
        """Send `packet` and read nothing."""
        os.write(self.fd, packet)

    def read(self, expect: int, timeout_s: float = 1.0) -> bytes:
        data = b""
        deadline = time.monotonic() + timeout_s
        while len(data) < expect:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self.fd], [], [], left)[0]:
                break
            data += os.read(self.fd, expect - len(data))
        return data

    def close(self) -> None:
        os.close(self.fd)
