"""Opening the servo bus a config asks for: simulated, emulated or real Dynamixel servos."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import dataclass

from app.config import Settings
from hardware.bus import ServoBus
from hardware.calibration import JointCalibration
from hardware.dynamixel import DynamixelBus, DynamixelConfig
from hardware.emulator import ServoEmulator
from hardware.registers import Reg


@dataclass(frozen=True)
class Backend:
    """An open bus and how to describe it to the operator."""

    bus: ServoBus
    kind: str  # sim | emulated | dynamixel
    description: str
    emulator: ServoEmulator | None = None  # for fault injection in tests and demos


def _calibrations(settings: Settings) -> tuple[JointCalibration, ...]:
    return tuple(JointCalibration(**joint.model_dump()) for joint in settings.hardware.joints)


def _dynamixel(settings: Settings, port: str) -> DynamixelBus:
    hw = settings.hardware
    config = DynamixelConfig(
        joints=_calibrations(settings), port=port, baudrate=hw.baud, max_tries=hw.max_tries
    )
    return DynamixelBus(config)


@contextlib.contextmanager
def open_backend(settings: Settings) -> Iterator[Backend]:
    """Connect the configured bus for the duration of the ``with`` block."""
    kind = settings.hardware.backend
    emulator: ServoEmulator | None = None
    if kind == "dynamixel":
        bus = _dynamixel(settings, settings.hardware.port)
        description = f"Dynamixel servos on {settings.hardware.port} at {settings.hardware.baud}"
    else:  # "sim" runs on the emulator until the MuJoCo twin backend is wired in
        ids = [joint.servo_id for joint in settings.hardware.joints]
        emulator = ServoEmulator(ids)
        with emulator.lock:
            for servo in emulator.servos:  # a tuned robot's bus: no 500 us reply delay
                servo.table.set(Reg.RETURN_DELAY_TIME, 0)
        emulator.start()
        bus = _dynamixel(settings, emulator.port)
        description = f"emulated XM430-W210 bus on {emulator.port} (dynamixel-sdk)"
    try:
        bus.connect()
        yield Backend(bus, kind, description, emulator)
    finally:
        with contextlib.suppress(Exception):
            bus.disconnect()
        if emulator is not None:
            emulator.stop()
