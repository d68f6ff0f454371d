"""The emulated XM430-W210 bus as tests use it: servo ids, a baud rate, a fast emulator,
a DynamixelBus config for it, and a raw pty client that speaks bytes without the SDK."""

from __future__ import annotations

import os
import select
import time
import tty

import dynamixel_sdk as sdk

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


# The emulator runs as a thread of the test: a loaded machine (CI runs beside two CPU
# hogs) can deschedule it past the SDK's ~34 ms status timeout, and a reply that comes late
# is a failed try. A config waits at least this long for each status packet, unless the
# test sets its own timeout (rx_timeout_s) or floor: those test the timeouts themselves.
# 0.25 s still let a healthy servo's reply miss with two workers beside two hogs; a wait
# costs only where a reply is really missing (a dropped or unplugged servo's test).
EMULATOR_REPLY_WAIT_S = 1.0
REBOOT_WAIT_S = 10.0  # how long a rebooted emulated servo may stay silent


def make_config(port: str, **overrides: object) -> DynamixelConfig:
    joints = tuple(JointCalibration(servo_id) for servo_id in IDS)
    settings = {"joints": joints, "port": port, "baudrate": BAUD, **overrides}
    if "rx_timeout_s" not in overrides:
        settings.setdefault("min_reply_wait_s", EMULATOR_REPLY_WAIT_S)
    # the product's 2 s is two of these tests' pings: CI's loaded run saw a servo back
    # after its Reboot, unheard within it
    settings.setdefault("reboot_timeout_s", REBOOT_WAIT_S)
    return DynamixelConfig(**settings)  # type: ignore[arg-type]


class PatientPort(sdk.PortHandler):
    """The SDK's own port, waiting at least EMULATOR_REPLY_WAIT_S for each status packet
    (the SDK's ~34 ms is sized for real servos, not for an emulator thread that a loaded
    machine deschedules); a test of a missing reply then waits that long for it."""

    def setPacketTimeout(self, packet_length):  # noqa: N802 (the SDK's name)
        super().setPacketTimeout(packet_length)
        self.packet_timeout = max(self.packet_timeout, EMULATOR_REPLY_WAIT_S * 1e3)

    def setPacketTimeoutMillis(self, msec):  # noqa: N802
        super().setPacketTimeoutMillis(msec)
        self.packet_timeout = max(self.packet_timeout, EMULATOR_REPLY_WAIT_S * 1e3)


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
