"""Test trajectories (thesis ch. 6.1): the sinusoid, planned with a smooth approach and stop.

A planned run is a timeline in the base frame: a jerk-limited approach (ruckig) from where
the robot is to the trajectory's start point, arriving with the trajectory's own velocity
and acceleration; the timed part; then a jerk-limited stop to rest. ``point_at(t)`` is
continuous in position, velocity and acceleration across the joins, so feed-forward (asking
for the point a little ahead) never steps either.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from ruckig import ControlInterface, InputParameter, Result, Ruckig, RuckigError, Trajectory

TWO_PI = 2.0 * math.pi
ROUNDING = 1.0 + 1e-6


@dataclass(frozen=True)
class SinusoidParams:
    """Per axis p(t) = offset + amplitude sin(2 pi f t + phase); defaults: thesis ch. 6.1.

    amplitude_m [m], frequency_hz [Hz], phase_rad [rad], offset_m [m] (base frame), each
    (x, y, z); duration_s: the timed part [s]; feedforward: command the point lead_s ahead.
    With a wrist, phi(t) = phi_amplitude_rad sin(2 pi phi_frequency_hz t) [rad] turns the
    tool as a fourth axis (0: the wrist is left alone, as without one). These defaults are
    the API's and the command line's too (app/runs/types.py, app/cli/run.py read them;
    the page's form takes them from GET /api/tests).
    """

    amplitude_m: tuple[float, float, float] = (0.05, 0.05, 0.08)
    frequency_hz: tuple[float, float, float] = (1.0, 1.0, 2.0)
    phase_rad: tuple[float, float, float] = (0.0, 0.0, 0.0)
    offset_m: tuple[float, float, float] = (0.0, 0.0, -0.24)
    duration_s: float = 10.0
    feedforward: bool = False
    phi_amplitude_rad: float = 0.0
    phi_frequency_hz: float = 0.0

    phi_field = "phi_amplitude_rad"  # the field to name when the wrist cannot do it

    @property
    def moves_wrist(self) -> bool:
        return self.phi_amplitude_rad != 0.0

    def phi_at(self, t: np.ndarray) -> np.ndarray:
        """The wrist angle phi [rad] at timed-part times ``t`` (*) [s], shape (*)."""
        omega = TWO_PI * self.phi_frequency_hz
        return self.phi_amplitude_rad * np.sin(omega * np.asarray(t, dtype=np.float64))

    def phi_peak_speed(self) -> float:
        """Largest |dphi/dt| [rad/s]."""
        return abs(self.phi_amplitude_rad) * TWO_PI * self.phi_frequency_hz

    def derivatives(self, t: np.ndarray, order: int) -> np.ndarray:
        """d^order p / dt^order at times ``t`` (*), shape (*, 3) [m/s^order]."""
        amplitude, phase = np.asarray(self.amplitude_m), np.asarray(self.phase_rad)
        omega = TWO_PI * np.asarray(self.frequency_hz)
        angle = np.asarray(t, dtype=np.float64)[..., None] * omega + phase
        value = amplitude * omega**order * np.sin(angle + order * math.pi / 2)
        return value + (np.asarray(self.offset_m) if order == 0 else 0.0)

    def peaks(self) -> tuple[float, float, float]:
        """Largest per-axis speed [m/s], acceleration [m/s^2] and jerk [m/s^3]."""
        amplitude = np.asarray(self.amplitude_m)
        omega = TWO_PI * np.asarray(self.frequency_hz)
        with np.errstate(over="ignore"):  # inf is an answer: the planner refuses it
            return tuple(float(np.max(np.abs(amplitude) * omega**k)) for k in (1, 2, 3))


def sinusoid_points(params: SinusoidParams, times_s: np.ndarray) -> np.ndarray:
    """The timed sinusoid at ``times_s`` (*) [s], shape (*, 3) [m] (for previews)."""
    return params.derivatives(times_s, 0)


def _ruckig(start: tuple, target: tuple, limits: tuple, velocity_only: bool) -> Trajectory:
    inp = InputParameter(3)
    inp.current_position, inp.current_velocity, inp.current_acceleration = start
    inp.target_position, inp.target_velocity, inp.target_acceleration = target
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = ([v] * 3 for v in limits)
    if velocity_only:
        inp.control_interface = ControlInterface.Velocity
    trajectory = Trajectory(3)
    try:
        result = Ruckig(3).calculate(inp, trajectory)
    except RuckigError as exc:  # e.g. a path too fast at its ends for any finite limit
        raise ValueError(
            "no smooth approach or stop exists: the path moves too fast at its start or end"
        ) from exc
    if result not in (Result.Working, Result.Finished):
        raise ValueError(f"no smooth approach or stop exists within the limits ({result})")
    return trajectory


class TimedPath(Protocol):
    """A test path: position and derivatives at time t, its length and its peaks (read
    only: frozen dataclasses and properties, e.g. a G-code program's ProgramPath)."""

    @property
    def duration_s(self) -> float: ...

    @property
    def feedforward(self) -> bool: ...

    def derivatives(self, t: np.ndarray, order: int) -> np.ndarray: ...

    def peaks(self) -> tuple[float, float, float]: ...


@dataclass(frozen=True)
class PlannedRun:
    """Approach + timed trajectory + stop, as one function of run time t [s]."""

    params: TimedPath
    approach: Trajectory = field(repr=False)
    stop: Trajectory = field(repr=False)

    @property
    def approach_s(self) -> float:
        return float(self.approach.duration)

    @property
    def duration_s(self) -> float:
        return self.approach_s + self.params.duration_s + float(self.stop.duration)

    def phase_at(self, t: float) -> str:
        if t < self.approach_s:
            return "approach"
        return "timed" if t <= self.approach_s + self.params.duration_s else "stop"

    @property
    def moves_wrist(self) -> bool:
        """The path turns the wrist (a ``phi_at`` and a non-zero phi part)."""
        return bool(getattr(self.params, "moves_wrist", False))

    def phi_at(self, t: float) -> float | None:
        """The wrist angle [rad] at run time ``t`` [s]: the path's phi at the start over the
        approach, at its end over the stop; None when the path leaves the wrist alone."""
        if not self.moves_wrist:
            return None
        timed = min(max(t - self.approach_s, 0.0), self.params.duration_s)
        return float(self.params.phi_at(np.array(timed)))  # type: ignore[attr-defined]

    def point_at(self, t: float) -> np.ndarray:
        """Goal point [m] at run time ``t`` [s] (clamped to the plan's ends)."""
        t = min(max(t, 0.0), self.duration_s)
        if t < self.approach_s:
            return np.array(self.approach.at_time(t)[0])
        timed = t - self.approach_s
        if timed <= self.params.duration_s:
            return self.params.derivatives(np.array(timed), 0)
        return np.array(self.stop.at_time(timed - self.params.duration_s)[0])

    def sample(self, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
        """(times (N,), points (N, 3)) every ``dt_s`` over the whole plan.

        The timed part is one batch call of the path's ``derivatives``; only the short
        approach and stop go through ruckig sample by sample. Same points as ``point_at``.
        """
        times = np.arange(0.0, self.duration_s + dt_s, dt_s)
        clamped = np.clip(times, 0.0, self.duration_s)
        timed = clamped - self.approach_s
        points = np.empty((len(times), 3))
        approach = clamped < self.approach_s
        stop = ~approach & (timed > self.params.duration_s)
        middle = ~approach & ~stop
        points[middle] = self.params.derivatives(timed[middle], 0)
        for index in np.flatnonzero(approach):
            points[index] = self.approach.at_time(float(clamped[index]))[0]
        for index in np.flatnonzero(stop):
            points[index] = self.stop.at_time(float(timed[index] - self.params.duration_s))[0]
        return times, points

    def samples(self, dt_s: float) -> int:
        """How many points :meth:`sample` gives for ``dt_s`` (without computing them)."""
        return math.ceil((self.duration_s + dt_s) / dt_s)


def plan_sinusoid(params: TimedPath, start_m: np.ndarray) -> PlannedRun:
    """Plan approach, timed path (sinusoid, chirp, waypoints) and stop from rest at ``start_m``."""
    speed, accel, jerk = params.peaks()
    if not all(math.isfinite(v) for v in (speed, accel, jerk)):
        raise ValueError("the path's speed, acceleration or jerk is not finite: too large")
    # The joins must be able to match the sinusoid's own motion, yet gentle when it is slow;
    # a hair over the peaks, or rounding puts the path's own join state beyond them.
    limits = (max(speed, 0.1) * ROUNDING, max(accel, 1.0) * ROUNDING, max(jerk, 10.0) * 2.0)
    begin = tuple(params.derivatives(np.array(0.0), k).tolist() for k in range(3))
    rest = (np.asarray(start_m, dtype=np.float64).tolist(), [0.0] * 3, [0.0] * 3)
    end = [params.derivatives(np.array(params.duration_s), k).tolist() for k in range(3)]
    approach = _join(rest, begin, limits, velocity_only=False)
    stop = _join(tuple(end), (end[0], [0.0] * 3, [0.0] * 3), limits, velocity_only=True)
    return PlannedRun(params, approach, stop)


def _join(start: tuple, target: tuple, limits: tuple, velocity_only: bool) -> Trajectory:
    """A join within ``limits``; failing that, with the speed headroom a join that starts
    or ends accelerating needs (a chirp's end: its speed grows by a^2 / 2j while the
    acceleration is brought to zero at jerk j)."""
    try:
        return _ruckig(start, target, limits, velocity_only)
    except ValueError:
        speed, accel, jerk = limits
        headroom = max(np.abs(start[2]).max(), np.abs(target[2]).max()) ** 2 / (2.0 * jerk)
        return _ruckig(start, target, (speed + headroom, accel, jerk), velocity_only)
