"""The guided homing procedure on a live bus: relax, hold the pose, read, save.

This is the step-by-step helper behind ``deltadash home`` (app/cli/home.py); the
arithmetic is hardware.calibration.home, a pure function.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

from hardware.calibration import JointCalibration, guided_homing, save
from hardware.dynamixel.driver import DynamixelBus


def home_bus(
    bus: DynamixelBus,
    config_path: str | Path,
    known_angles_rad: Sequence[float] | float = 0.0,
    confirm: Callable[[str], object] = input,
) -> tuple[JointCalibration, ...]:
    """Home every joint of a connected bus and save the records into `config_path`.

    Torque goes off so the operator can place the upper links by hand at the known pose
    (0 rad = horizontal jig); the new zero offsets are computed from the present raw
    positions, written to the config's ``[[hardware.joints]]`` and used by `bus` from now on.
    """
    bus.torque(False)
    homed = guided_homing(bus.config.joints, bus.read_ticks, known_angles_rad, confirm)
    save(config_path, homed)
    bus.config = replace(bus.config, joints=homed)
    return homed
