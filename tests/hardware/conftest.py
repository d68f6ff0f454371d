"""Fixtures of tests/hardware and its dynamixel/ and emulator/ folders: an emulated
XM430-W210 bus on a pty, and a DynamixelBus connected to it (helpers in
tests/support/servo_emulator.py).

Every fixture stops what it started (emulator thread, pty, serial port) in its teardown,
so a failing test cannot leave a thread answering on a stale pty for the next one.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from hardware.dynamixel.driver import DynamixelBus
from hardware.emulator import ServoEmulator
from tests.support.servo_emulator import IDS, fast, make_config


@pytest.fixture
def emulator() -> Iterator[ServoEmulator]:
    emu = fast(ServoEmulator(IDS))
    emu.start()
    try:
        yield emu
    finally:
        emu.stop()


@pytest.fixture
def bus(emulator: ServoEmulator) -> Iterator[DynamixelBus]:
    dxl = DynamixelBus(make_config(emulator.port))
    dxl.connect()
    try:
        yield dxl
    finally:
        dxl.disconnect()


@pytest.fixture
def patient_bus(emulator: ServoEmulator) -> Iterator[DynamixelBus]:
    """A bus that waits 1 s for each status packet: for tests that tell which servo
    failed, so that a healthy servo answering late on a loaded machine is not counted."""
    dxl = DynamixelBus(make_config(emulator.port, rx_timeout_s=1.0))
    dxl.connect()
    try:
        yield dxl
    finally:
        dxl.disconnect()
