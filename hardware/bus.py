"""The servo-bus interface the control loop uses, and the values that cross it.

The loop sees radians, rad/s, amperes, volts and degrees Celsius; ticks and register units
stay below this line (hardware/dynamixel/). A read that fails raises (hardware/errors.py); it
never returns a state built from a partial or corrupt reply. Implementations: `DynamixelBus`
(hardware/dynamixel/driver.py) on a real or emulated bus, and the simulated robot's `SimBus`
and `ProcessSimBus` (hardware/sim/), which are also `SimulatedBus`es.

Every method raises a `BusError` subclass (hardware/errors.py) and nothing else on a bus
failure: `NotConnectedError` before connect() or after disconnect(); `CommError` when no
valid status packet came back within the bounded retries; `ServoStatusError` when a servo
refused the instruction; `HardwareError` when a servo is latched in a hardware fault; a plain
`BusError` for what fits none of these (a wrong model number, a simulator process gone).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, fields, replace
from typing import Any, Protocol, runtime_checkable

import numpy as np

from hardware.base_motion import BaseMotion


class OperatingMode(enum.IntEnum):
    """What the servos control: the X series' Operating Mode (11) values, which the control
    table (hardware/dynamixel/control_table.py) stores as they are."""

    CURRENT = 0
    VELOCITY = 1
    POSITION = 3
    EXTENDED_POSITION = 4
    CURRENT_BASED_POSITION = 5
    PWM = 16


@dataclass(frozen=True)
class ServoInfo:
    """What a ping finds: the servo id, its model number (1030 = XM430-W210) and firmware."""

    servo_id: int
    model_number: int
    firmware_version: int


def reading(unit: str, description: str) -> Any:
    """A servo reading of :class:`JointState`: a per-joint column that every layer above
    (the loop's snapshot, ``/api/status``, the process bus's shared frame, the wrist's
    split) carries by its name, ``unit`` and ``description``, so a new register read is
    declared here once (:data:`READINGS`)."""
    return field(metadata={"unit": unit, "description": description})


@dataclass(frozen=True)
class JointState:
    """One consistent read of all joints, in joint order; arrays have shape (n_joints,).

    position_rad: joint angle [rad] (calibrated: 0 = upper link horizontal, + down).
    The servo readings (:data:`READINGS`, each a float column with its unit) follow it.
    hardware_errors: per joint, the names of the Hardware Error Status bits set (empty if
    none); moving: per joint, the servo's Moving flag; stamp_s: time.monotonic() at read [s]
    (a simulator's state: when the simulator produced it).
    sim_time_s: a simulated robot's simulated time at this state [s], None for real servos:
    two reads with the same simulated time are the same state, the second one stale (the
    simulator did not step in between). A real bus's state is fresh by construction: a read
    either gets every servo's reply or raises.
    torque_enabled: per joint, the servo's Torque Enable (64) as read from the servo, not
    as last written: False for a servo whose Shutdown turned its torque off after an
    overload or other hardware error (the arm then sags however torque was asked); None
    where a bus does not know it.
    """

    position_rad: np.ndarray
    velocity_rad_s: np.ndarray = reading("rad/s", "joint velocity (Present Velocity)")
    current_a: np.ndarray = reading(
        "A", "motor current (Present Current), signed in the joint's direction"
    )
    voltage_v: np.ndarray = reading("V", "input voltage (Present Input Voltage)")
    temperature_c: np.ndarray = reading("degC", "internal temperature (Present Temperature)")
    pwm: np.ndarray = reading(
        "1", "PWM duty cycle (Present PWM / 885), signed in the joint's direction; 1 = full"
    )
    moving: np.ndarray = field(kw_only=True)
    hardware_errors: tuple[tuple[str, ...], ...] = field(kw_only=True)
    stamp_s: float = field(kw_only=True)
    sim_time_s: float | None = field(default=None, kw_only=True)
    torque_enabled: tuple[bool, ...] | None = field(default=None, kw_only=True)

    def readings(self) -> dict[str, np.ndarray]:
        """The servo readings by name (:data:`READINGS`), each of shape (n_joints,)."""
        return {name: getattr(self, name) for name in READINGS}

    def joints(self, count: int) -> JointState:
        """This read's first ``count`` joints (e.g. the legs of a read that has a wrist)."""
        per_joint = {name: getattr(self, name)[:count] for name in ("position_rad", *READINGS)}
        torque = None if self.torque_enabled is None else tuple(self.torque_enabled[:count])
        return replace(
            self,
            **per_joint,
            moving=self.moving[:count],
            hardware_errors=tuple(self.hardware_errors[:count]),
            torque_enabled=torque,
        )

    @property
    def faulted(self) -> bool:
        """True if any joint reports a hardware error."""
        return any(self.hardware_errors)


#: The servo readings of a :class:`JointState`, in order: name -> (unit, description).
READINGS: dict[str, tuple[str, str]] = {
    f.name: (f.metadata["unit"], f.metadata["description"])
    for f in fields(JointState)
    if "unit" in f.metadata
}


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

    def as_dict(self) -> dict[str, int]:
        """The short form the API and the config use: p, i, d, ff1, ff2 (register units)."""
        return {
            "p": self.p,
            "i": self.i,
            "d": self.d,
            "ff1": self.feedforward_1st,
            "ff2": self.feedforward_2nd,
        }


def per_joint(gains: PositionGains | Sequence[PositionGains], n: int) -> list[PositionGains]:
    """`gains` as one PositionGains per joint (n of them): a single set repeated, or a
    sequence checked to hold n. Raises ValueError on a sequence of another length."""
    if isinstance(gains, PositionGains):
        return [gains] * n
    listed = list(gains)
    if len(listed) != n:
        raise ValueError(f"gains for {len(listed)} joints: the bus has {n}")
    return listed


def goal_current_units(
    currents_a: Sequence[float], limits_units: Sequence[int], unit_a: float
) -> list[int]:
    """Goal Current (102) register values for `currents_a` [A], one per joint (n,).

    Each current is rounded to whole units of `unit_a` [A] (the XM430's 2.69 mA) and must
    lie within 0 .. that joint's Current Limit (38), `limits_units` [units] (n,).

    Raises ValueError for a sequence of another length than `limits_units`, or naming the
    joint (1-based), the value and the limit for a value that is not finite, negative or
    above the limit; nothing is returned then, so a caller writes all or nothing.
    """
    values = [float(c) for c in currents_a]
    if len(values) != len(limits_units):
        raise ValueError(f"goal currents for {len(values)} joints: the bus has {len(limits_units)}")
    units = []
    for joint, (value, limit) in enumerate(zip(values, limits_units, strict=True), start=1):
        if not math.isfinite(value) or value < 0:
            raise ValueError(f"goal current of joint {joint}: {value} A must be finite and >= 0")
        count = round(value / unit_a)
        if count > limit:
            raise ValueError(
                f"goal current of joint {joint}: {value} A is above its Current Limit "
                f"{limit * unit_a:.4g} A ({limit} units of {unit_a * 1e3:g} mA)"
            )
        units.append(count)
    return units


@dataclass(frozen=True)
class BusStats:
    """Counters since connect: transactions, failed tries, retries, and give-ups; and
    status packets discarded as answers to another request (late, duplicated, foreign)."""

    transactions: int = 0
    failed_tries: int = 0
    retries: int = 0
    failures: int = 0
    discarded: int = 0


@runtime_checkable
class ServoBus(Protocol):
    """A bus of position-controlled joint servos, addressed in joint order.

    An optional class attribute ``carries_load`` (True on the Dynamixel driver and the
    twin's buses) says the servos move links under gravity, so the loop's gravity
    compensation applies by default (app/config.py ``Settings.gravity_on``); fakes and
    the emulator leave it out.
    """

    def connect(self) -> None:
        """Open the port and check every configured servo answers a ping.

        Raises CommError (port will not open, a servo is missing), BusError (a servo of the
        wrong model), NotConnectedError (ProcessSimBus: the simulator process did not start);
        the port is closed again when it raises.
        """

    def disconnect(self) -> None:
        """Close the port (torque is left as it is; call torque(False) first to relax).

        Never raises: a vanished device is closed all the same.
        """

    def scan(self, ids: Sequence[int] | None = None) -> list[ServoInfo]:
        """Ping `ids` (default: the configured joints); absent servos are left out.

        Raises NotConnectedError; CommError or ServoStatusError if a servo that answered
        the ping then fails the firmware read.
        """

    def torque(self, enabled: bool) -> None:
        """Torque Enable on all joints.

        Raises NotConnectedError, CommError, ServoStatusError; HardwareError when enabling
        a servo latched in a hardware fault (reboot clears it).
        """

    def set_operating_mode(self, mode: OperatingMode) -> None:
        """Operating Mode on all joints (an EEPROM item: torque must be off).

        Raises NotConnectedError, CommError; ServoStatusError (the real servo's Access
        Error) or BusError (the simulator) if torque is on.
        """

    def set_goal_current(self, currents_a: Sequence[float]) -> None:
        """Goal Current (102) per joint [A], shape (n_joints,), in joint order.

        Each value must be finite and within 0 .. the servo's Current Limit (38) (XM430:
        1193 units of 2.69 mA = 3.209 A); it is rounded to whole 2.69 mA units. In
        Current-based Position Control Mode (5) the firmware bounds the motor current,
        and so the output torque (Kt * Goal Current), by it; in Current Control Mode (0)
        it is the target current; other modes ignore it. A RAM item: it may be written
        with torque on.

        Raises ValueError naming the joint, the value and the limit (nothing written), or
        for a sequence of the wrong length; NotConnectedError, CommError,
        ServoStatusError.
        """

    def write_goal(self, positions_rad: Sequence[float]) -> None:
        """Goal joint angles [rad] for all joints, one packet; clamped to calibrated limits.

        Raises NotConnectedError, CommError (the write could not be sent).
        """

    def read_state(self) -> JointState:
        """Present state of all joints in one transaction; raises rather than guess.

        Raises NotConnectedError; CommError when any servo's reply is missing or corrupt
        after the bounded retries. A latched hardware error is reported in
        `JointState.hardware_errors`, not raised.
        """

    def set_profile(self, velocity_rad_s: float, acceleration_rad_s2: float) -> None:
        """Profile Velocity [rad/s] and Acceleration [rad/s^2] on all joints (0 = unlimited).

        A positive value too small for one register unit is written as one unit, never as
        0 (unlimited); only 0 asked is unlimited.

        Raises ValueError for a negative value; NotConnectedError, CommError,
        ServoStatusError.
        """

    def set_gains(self, gains: PositionGains | Sequence[PositionGains]) -> None:
        """Position PID and feed-forward gains: one set for all joints, or one per joint in
        joint order (`per_joint`).

        Raises ValueError (a sequence of the wrong length); NotConnectedError, CommError,
        ServoStatusError (a gain out of range).
        """

    def read_gains(self) -> list[PositionGains]:
        """Each joint's position PID and feed-forward gains as its servo holds them, in
        joint order.

        Raises NotConnectedError, CommError, ServoStatusError.
        """

    def reboot(self, ids: Sequence[int] | None = None) -> None:
        """Reboot servos (default all joints) to clear a latched hardware error; returns
        once they answer again (with torque off), so nothing reaches a servo still booting.

        Raises NotConnectedError; CommError if a servo does not answer or does not come back.
        """

    @property
    def stats(self) -> BusStats:
        """Transaction and retry counters (never raises)."""


@runtime_checkable
class SimulatedBus(Protocol):
    """What a simulated robot's bus can do beyond a `ServoBus`: the true platform, a moving base.

    `SimBus` and `ProcessSimBus` (hardware/sim/) are both; `DynamixelBus` is not. Check with
    ``isinstance(bus, SimulatedBus)`` rather than probing for the method names.
    """

    def measure_platform(self, at_last_read: bool = False) -> np.ndarray:
        """The external measurement of the platform in the base frame [m], shape (3,): the
        true centre plus the marker offset plus noise; with ``at_last_read`` at the instant
        of the last read_state.

        Raises NotConnectedError (ProcessSimBus before connect), BusError (its shared state
        stayed locked).
        """

    def set_base_motion(self, motion: BaseMotion) -> None:
        """The drone's attitude, acceleration and turning, acting on the arm from now on.

        Raises NotConnectedError, BusError (ProcessSimBus: the simulator process is gone).
        """
