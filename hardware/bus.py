"""The servo-bus interface the control loop uses, and the values that cross it.

The loop sees radians, rad/s, amperes, volts and degrees Celsius; ticks and register units
stay below this line (hardware/dynamixel/control_table.py, driver.py). A read that fails
raises (hardware/errors.py); it never returns a state built from a partial or corrupt reply.
Implementations: `DynamixelBus` (hardware/dynamixel/driver.py) on a real or emulated bus.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from hardware.dynamixel.control_table import OperatingMode


@dataclass(frozen=True)
class ServoInfo:
    """What a ping finds: the servo id, its model number (1030 = XM430-W210) and firmware."""

    servo_id: int
    model_number: int
    firmware_version: int


@dataclass(frozen=True)
class JointState:
    """One consistent read of all joints, in joint order; arrays have shape (n_joints,).

    position_rad: joint angle [rad] (calibrated: 0 = upper link horizontal, + down)
    velocity_rad_s: joint velocity [rad/s]; current_a: motor current [A] (signed, in the
    joint's direction); voltage_v: input voltage [V]; temperature_c: [degC];
    hardware_errors: per joint, the names of the Hardware Error Status bits set (empty if
    none); moving: per joint, the servo's Moving flag; stamp_s: time.monotonic() at read [s].
    """

    position_rad: np.ndarray
    velocity_rad_s: np.ndarray
    current_a: np.ndarray
    voltage_v: np.ndarray
    temperature_c: np.ndarray
    moving: np.ndarray
    hardware_errors: tuple[tuple[str, ...], ...]
    stamp_s: float

    @property
    def faulted(self) -> bool:
        """True if any joint reports a hardware error."""
        return any(self.hardware_errors)


@dataclass(frozen=True)
class PositionGains:
    """Position PID and feed-forward gains, in the servo's register units (dimensionless).

    The XM430 computes KpP = p / 128, KiP = i / 65536, KdP = d / 16, and the feed-forward
    gains ff1 / 4 (velocity) and ff2 / 4 (acceleration); we keep raw values so a tuning
    copied from the ROBOTIS Wizard means the same thing here.
    """

    p: int = 800
    i: int = 0
    d: int = 0
    feedforward_1st: int = 0
    feedforward_2nd: int = 0


@dataclass(frozen=True)
class BusStats:
    """Counters since connect: transactions, failed tries, retries, and give-ups."""

    transactions: int = 0
    failed_tries: int = 0
    retries: int = 0
    failures: int = 0


@runtime_checkable
class ServoBus(Protocol):
    """A bus of position-controlled joint servos, addressed in joint order."""

    def connect(self) -> None:
        """Open the port and check every configured servo answers a ping."""

    def disconnect(self) -> None:
        """Close the port (torque is left as it is; call torque(False) first to relax)."""

    def scan(self, ids: Sequence[int] | None = None) -> list[ServoInfo]:
        """Ping `ids` (default: the configured joints); absent servos are left out."""

    def torque(self, enabled: bool) -> None:
        """Torque Enable on all joints."""

    def set_operating_mode(self, mode: OperatingMode) -> None:
        """Operating Mode on all joints (an EEPROM item: torque must be off)."""

    def write_goal(self, positions_rad: Sequence[float]) -> None:
        """Goal joint angles [rad] for all joints, one packet; clamped to calibrated limits."""

    def read_state(self) -> JointState:
        """Present state of all joints in one transaction; raises rather than guess."""

    def set_profile(self, velocity_rad_s: float, acceleration_rad_s2: float) -> None:
        """Profile Velocity [rad/s] and Acceleration [rad/s^2] on all joints (0 = unlimited)."""

    def set_gains(self, gains: PositionGains) -> None:
        """Position PID and feed-forward gains on all joints."""

    def reboot(self, ids: Sequence[int] | None = None) -> None:
        """Reboot servos (default all joints) to clear a latched hardware error."""

    @property
    def stats(self) -> BusStats:
        """Transaction and retry counters."""
