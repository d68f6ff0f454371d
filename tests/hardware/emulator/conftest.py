"""Fixtures: raw SDK handles and a raw byte client on the emulated bus
(the emulator fixture is tests/hardware/conftest.py's)."""

from __future__ import annotations

from collections.abc import Iterator

import dynamixel_sdk as sdk
import pytest

from hardware.emulator import ServoEmulator
from tests.support.servo_emulator import BAUD, PatientPort, RawPort


@pytest.fixture
def sdk_port(emulator: ServoEmulator) -> Iterator[tuple[sdk.PortHandler, object]]:
    port = PatientPort(emulator.port)
    assert port.openPort() and port.setBaudRate(BAUD)
    try:
        yield port, sdk.PacketHandler(2.0)
    finally:
        port.closePort()


@pytest.fixture
def raw(emulator: ServoEmulator) -> Iterator[RawPort]:
    port = RawPort(emulator.port)
    try:
        yield port
    finally:
        port.close()
