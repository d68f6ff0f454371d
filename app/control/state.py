"""What the control loop publishes each tick: faults and an immutable snapshot."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

_NAN3 = np.full(3, np.nan)


@dataclass(frozen=True)
class Fault:
    """Why the robot stopped: ``source`` is bus, servo, following, gate or loop."""

    source: str
    reason: str
    servo_id: int | None = None
    time_s: float = 0.0

    def as_dict(self) -> dict:
        return {
            "source": self.source,
            "reason": self.reason,
            "servo_id": self.servo_id,
            "time_s": self.time_s,
        }


@dataclass(frozen=True)
class Snapshot:
    """The loop's state after one tick, in SI units and the base frame.

    Arrays are shape (3,); NaN where unknown (no successful read yet, FK failed).
    """

    time_s: float = 0.0
    tick: int = 0
    mode: str = "idle"
    torque: bool = False
    estopped: bool = False
    faults: tuple[Fault, ...] = ()
    warning: str | None = None
    joints_measured_rad: np.ndarray = field(default_factory=lambda: _NAN3)
    point_measured_m: np.ndarray = field(default_factory=lambda: _NAN3)
    joints_commanded_rad: np.ndarray = field(default_factory=lambda: _NAN3)
    point_commanded_m: np.ndarray = field(default_factory=lambda: _NAN3)
    goal_m: np.ndarray = field(default_factory=lambda: _NAN3)
    velocity_rad_s: np.ndarray = field(default_factory=lambda: _NAN3)
    current_a: np.ndarray = field(default_factory=lambda: _NAN3)
    voltage_v: np.ndarray = field(default_factory=lambda: _NAN3)
    temperature_c: np.ndarray = field(default_factory=lambda: _NAN3)
    moving: tuple[bool, ...] = (False, False, False)
    hardware_errors: tuple[tuple[str, ...], ...] = ((), (), ())
    missed_reads: int = 0
    phase: str = ""
    lateness_ms: float = 0.0
    extra: dict | None = None
    external_m: np.ndarray = field(default_factory=lambda: _NAN3)  # e.g. motion capture

    @property
    def tracking_error_m(self) -> np.ndarray:
        """Commanded minus measured platform position [m]."""
        return self.point_commanded_m - self.point_measured_m
