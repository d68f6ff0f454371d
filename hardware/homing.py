"""The guided homing procedure on a live bus: relax, hold the pose, read, check, save.

This is the step-by-step helper behind ``deltadash home`` (app/cli/home.py); the
arithmetic is hardware.calibration.home, a pure function, and the reach of each servo's
operating mode is hardware.seam.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

from hardware.bus import OperatingMode
from hardware.calibration import JointCalibration, guided_homing, save
from hardware.dynamixel.driver import DynamixelBus
from hardware.seam import check_joint, single_turn


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

    A servo in Position Control Mode is read as it will count once torque is on (one turn,
    hardware.seam.single_turn: with torque off its count runs on past the seam). Each new
    joint range is checked against what the servo's operating mode can reach before
    anything is saved. Raises SeamError (nothing saved) naming the servo, the joint, the
    ticks and the fix: the range crosses the encoder's 0/4095 seam in Position Control
    Mode (turn the link on its horn, or use Extended Position Control Mode), or a Homing
    Offset leaves it out of reach (the message gives the register value that does not).
    """
    bus.torque(False)
    setups = bus.read_setups()

    def read_ticks() -> dict[int, int]:
        ticks = bus.read_ticks()
        for servo_id, setup in setups.items():
            if setup.mode == OperatingMode.POSITION:
                ticks[servo_id] = single_turn(ticks[servo_id], setup.offset_in_force)
        return ticks

    homed = guided_homing(bus.config.joints, read_ticks, known_angles_rad, confirm)
    for joint, cal in enumerate(homed, start=1):
        check_joint(cal, setups[cal.servo_id], joint)
    save(config_path, homed)
    bus.config = replace(bus.config, joints=homed)
    return homed
