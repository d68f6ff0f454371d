"""More timed paths for test runs: a chirp for identifying the servo response, waypoints
with timing (pick-and-place, rasters), a step on one axis and a step of one joint. Each
offers what PlannedRun needs: ``derivatives(t, order)``, ``duration_s``, ``peaks()`` and
``feedforward``. The defaults written here are the API's too: the run types' request
models (app/runs/types.py) take theirs from these dataclasses.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class ChirpParams:
    """Linear chirp along ``axis``: a sin(2 pi (f0 t + (f1 - f0) t^2 / (2 T))) about ``offset_m``.

    A frequency sweep shows the servo's lag and gain at every frequency in one run (thesis
    ch. 6.3: tuning the servo gains).
    """

    axis: int = 2
    amplitude_m: float = 0.02
    f0_hz: float = 0.2
    f1_hz: float = 3.0
    offset_m: tuple[float, float, float] = (0.0, 0.0, -0.24)
    duration_s: float = 10.0
    feedforward: bool = False

    def derivatives(self, t: np.ndarray, order: int) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)
        rate = (self.f1_hz - self.f0_hz) / self.duration_s
        phase = TWO_PI * (self.f0_hz * t + 0.5 * rate * t * t)
        omega = TWO_PI * (self.f0_hz + rate * t)  # d phase / dt
        a = self.amplitude_m
        value = {
            0: a * np.sin(phase),
            1: a * omega * np.cos(phase),
            2: a * (TWO_PI * rate * np.cos(phase) - omega**2 * np.sin(phase)),
        }[order]
        out = np.zeros((*t.shape, 3))
        out[..., self.axis] = value
        return out + (np.asarray(self.offset_m) if order == 0 else 0.0)

    def peaks(self) -> tuple[float, float, float]:
        # bounds of |derivatives|: the sweep's rate adds to the acceleration and jerk
        omega = TWO_PI * max(self.f0_hz, self.f1_hz)
        sweep = TWO_PI * abs(self.f1_hz - self.f0_hz) / self.duration_s
        a = abs(self.amplitude_m)
        return a * omega, a * (omega**2 + sweep), a * (omega**3 + 3 * sweep * omega)


def _quintic(s: np.ndarray, order: int) -> np.ndarray:
    """Minimum-jerk blend 0 -> 1 on s in [0, 1] and its derivatives w.r.t. s."""
    s = np.clip(s, 0.0, 1.0)
    return {
        0: 10 * s**3 - 15 * s**4 + 6 * s**5,
        1: 30 * s**2 - 60 * s**3 + 30 * s**4,
        2: 60 * s - 180 * s**2 + 120 * s**3,
    }[order]


@dataclass(frozen=True)
class WaypointParams:
    """Points [m] reached at times [s] (the first at t = 0), resting at each: minimum-jerk
    segments between them, so velocity and acceleration are zero at every waypoint."""

    points_m: tuple[tuple[float, float, float], ...]
    times_s: tuple[float, ...]
    feedforward: bool = False

    def __post_init__(self) -> None:
        if len(self.points_m) < 2 or len(self.points_m) != len(self.times_s):
            raise ValueError("waypoints: give 2 or more points and one time per point")
        if self.times_s[0] != 0.0 or not all(np.diff(self.times_s) > 0):
            raise ValueError("waypoints: times_s must start at 0 and increase")

    @property
    def duration_s(self) -> float:
        return float(self.times_s[-1])

    @cached_property
    def _arrays(self) -> tuple[np.ndarray, np.ndarray]:
        # converted once: the loop asks for a point every tick, the check for thousands
        return np.asarray(self.times_s, dtype=np.float64), np.asarray(self.points_m, np.float64)

    def derivatives(self, t: np.ndarray, order: int) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)
        times, points = self._arrays
        k = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2)
        span = times[k + 1] - times[k]
        s = (t - times[k]) / span
        delta = points[k + 1] - points[k]
        blend = _quintic(s, order)[..., None] / span[..., None] ** order
        return (points[k] if order == 0 else 0.0) + blend * delta

    def peaks(self) -> tuple[float, float, float]:
        delta = np.abs(np.diff(np.asarray(self.points_m), axis=0)).max(axis=1)
        span = np.diff(self.times_s)
        # peaks of the quintic: 1.875 / T, 5.774 / T^2, 60 / T^3 per unit distance
        return tuple(
            float(np.max(c * delta / span**p)) for c, p in ((1.875, 1), (5.774, 2), (60.0, 3))
        )


@dataclass(frozen=True)
class StepParams:
    """A position step of ``size_m`` along ``axis`` at ``step_at_s``, then hold: the servo's
    step response (rise time, overshoot, lag) in one run. Small steps (a few mm) pass the
    gate's joint-speed limit unchanged; larger ones are refused by the feasibility check."""

    axis: int = 2
    size_m: float = 0.005
    step_at_s: float = 0.5
    offset_m: tuple[float, float, float] = (0.0, 0.0, -0.24)
    duration_s: float = 2.0
    feedforward: bool = False
    phi_step_rad: float = 0.0  # with a wrist: a step of phi [rad] at step_at_s too

    phi_field = "phi_step_rad"  # the field to name when the wrist cannot do it

    @property
    def moves_wrist(self) -> bool:
        return self.phi_step_rad != 0.0

    def phi_at(self, t: np.ndarray) -> np.ndarray:
        """The wrist angle phi [rad] at timed-part times ``t`` (*) [s]: 0, then the step."""
        return np.where(np.asarray(t, dtype=np.float64) >= self.step_at_s, self.phi_step_rad, 0.0)

    def phi_peak_speed(self) -> float:
        return 0.0  # a step: the tick turns the wrist at its speed limit

    def derivatives(self, t: np.ndarray, order: int) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)
        out = np.zeros((*t.shape, 3))
        if order == 0:
            out[..., self.axis] = np.where(t >= self.step_at_s, self.size_m, 0.0)
            out += np.asarray(self.offset_m)
        return out

    def peaks(self) -> tuple[float, float, float]:
        return 0.0, 0.0, 0.0  # the approach and stop join it at rest


@dataclass(frozen=True)
class JointStepParams:
    """A step of one joint (``joint``, 1..3) by ``step_rad`` [rad] at ``step_at_s``, the
    others held, from the joints ``start_rad`` (3,) [rad], then hold: one servo's step
    response in joint space (the servo panel's step). The goal climbs at ``ramp_rad_s``
    [rad/s] (the loop's joint speed limit, a little under it: a step beyond what one tick
    may move is what the loop would cut anyway): 5 deg take 13 ms at 90 % of 7.5 rad/s.

    The loop takes tool tips: ``tip_of`` maps joints (*, 3) [rad] to the tip (*, 3) [m]
    they put it at (the robot's FK and the tool at the loop's wrist angle), so the loop's
    IK, on the branch nearest the arm, gives the joints back. With a wrist held away from
    0, ``phi_rad`` is that angle (the feasibility check sees the tips at it)."""

    joint: int
    start_rad: tuple[float, float, float]
    step_rad: float
    ramp_rad_s: float
    tip_of: Callable[[np.ndarray], np.ndarray] = field(repr=False, compare=False)
    step_at_s: float = 0.2
    duration_s: float = 1.0
    phi_rad: float = 0.0
    feedforward: bool = False

    phi_field = "phi_rad"  # the field to name when the wrist cannot hold it

    def __post_init__(self) -> None:
        if self.joint not in (1, 2, 3):
            raise ValueError(f"joint {self.joint}: the legs are 1, 2, 3")
        if not (self.ramp_rad_s > 0 and 0 <= self.step_at_s < self.duration_s):
            raise ValueError("a joint step needs a ramp speed > 0 and its step inside the run")

    @property
    def rise_s(self) -> float:
        """How long the goal climbs [s]."""
        return abs(self.step_rad) / self.ramp_rad_s

    def joints_at(self, t: np.ndarray) -> np.ndarray:
        """The joint goal (*, 3) [rad] at timed-part times ``t`` (*) [s]."""
        t = np.asarray(t, dtype=np.float64)
        climbed = np.clip((t - self.step_at_s) / self.rise_s, 0.0, 1.0) * self.step_rad
        out = np.broadcast_to(np.asarray(self.start_rad), (*t.shape, 3)).copy()
        out[..., self.joint - 1] += climbed
        return out

    @property
    def moves_wrist(self) -> bool:
        return self.phi_rad != 0.0

    def phi_at(self, t: np.ndarray) -> np.ndarray:
        """The wrist held at ``phi_rad`` throughout."""
        return np.full(np.shape(t), self.phi_rad)

    def phi_peak_speed(self) -> float:
        return 0.0

    def derivatives(self, t: np.ndarray, order: int) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)
        if order == 0:
            return self.tip_of(self.joints_at(t))
        # central differences: zero (exactly) where the goal stands, which is where the
        # planner asks (the run's ends); finite, not an impulse, on the short climb
        h = 1e-4
        below, above = self.derivatives(t - h, order - 1), self.derivatives(t + h, order - 1)
        return (above - below) / (2.0 * h)

    def peaks(self) -> tuple[float, float, float]:
        return 0.0, 0.0, 0.0  # the approach and stop join it at rest
