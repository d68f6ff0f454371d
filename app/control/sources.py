"""Goal sources: what the loop asks of the robot each tick, in the active mode.

A source returns a ``Setpoint`` per tick: a platform point (base frame) or joint angles,
with the velocity it carries. Jog follows an operator target that may jump, along an
online jerk-limited path (ruckig); move-to runs one precomputed ruckig trajectory in
Cartesian or joint space. Test trajectories and hold-in-world plug in the same way.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from ruckig import ControlInterface, InputParameter, OutputParameter, Result, Ruckig

from app.control.errors import GoalRejected


@dataclass(frozen=True)
class Setpoint:
    """One tick's request: exactly one of ``point_m`` (3,), the tool tip [m], or
    ``joints_rad`` (3,); ``phi_rad``: the wrist angle [rad] for the tip (None: the one the
    loop holds, ``LoopState.phi_rad``).

    goal_m: the nominal goal this tick (a test run's trajectory point, when feed-forward
    commands a point ahead of it); goal_phi_rad: the wrist's, likewise (None: ``phi_rad``;
    a move's target while the wrist turns towards it along the path); phase: the run's
    phase for logs (approach, timed, stop).
    """

    point_m: np.ndarray | None = None
    joints_rad: np.ndarray | None = None
    phi_rad: float | None = None
    finished: bool = False
    goal_m: np.ndarray | None = None
    goal_phi_rad: float | None = None
    phase: str = ""
    extra: dict | None = None  # mode-specific values for logs (e.g. world-frame positions)
    warning: str | None = None  # shown in status; with no point/joints the robot holds
    fault: str | None = None  # stop and fault with this reason


class GoalSource(Protocol):
    """A mode's goal generator; called from the control thread only."""

    name: str

    def next(self, dt_s: float) -> Setpoint:
        """The setpoint for the tick ``dt_s`` [s] after the previous one."""


@dataclass(frozen=True)
class Progress:
    """How far a timed source (a test run) is, in run time [s]: ``elapsed_s`` of
    ``duration_s`` for the whole run (approach, test and stop), ``test_elapsed_s`` of
    ``test_duration_s`` for the test part alone; ``phase`` as in its setpoints."""

    phase: str
    elapsed_s: float
    duration_s: float
    test_elapsed_s: float
    test_duration_s: float

    @classmethod
    def at(
        cls, phase: str, t_s: float, approach_s: float, test_s: float, stop_s: float = 0.0
    ) -> Progress:
        """At run time ``t_s`` [s] of a run of ``approach_s``, ``test_s`` then ``stop_s``."""
        total = approach_s + test_s + stop_s
        test = min(max(t_s - approach_s, 0.0), test_s)
        return cls(phase, min(t_s, total), total, test, test_s)


@runtime_checkable
class Progressing(Protocol):
    """A source that can say how far it is (a page reloaded mid-run shows the real
    progress); read from other threads, so it only reads its own floats."""

    def progress(self) -> Progress: ...


MIN_SPEED_M_S = 1e-4  # ruckig needs a positive limit on every axis, even one not jogged


@dataclass(frozen=True)
class Limits:
    """Per-axis velocity, acceleration and jerk limits [units/s, /s^2, /s^3]."""

    velocity: float
    acceleration: float
    jerk: float


def _ruckig_input(start: np.ndarray, limits: Sequence[Limits]) -> InputParameter:
    """At rest at ``start`` (n,), targeting it, with one `Limits` per axis (n of them)."""
    n = len(start)
    inp = InputParameter(n)
    inp.current_position = start.tolist()
    inp.current_velocity = [0.0] * n
    inp.current_acceleration = [0.0] * n
    inp.target_position = start.tolist()
    inp.max_velocity = [a.velocity for a in limits]
    inp.max_acceleration = [a.acceleration for a in limits]
    inp.max_jerk = [a.jerk for a in limits]
    return inp


@dataclass(frozen=True)
class WristAxis:
    """The wrist as a move's fourth coordinated axis: from ``start_rad`` to ``target_rad``
    [rad] within ``limits`` (its speed limit [rad/s], acceleration, jerk)."""

    start_rad: float
    target_rad: float
    limits: Limits


AT_REST = 1e-9  # a jog's offset from its target [m], speed [m/s] and acceleration [m/s^2]
# below this stands still: ruckig ends a path within rounding of its target


class JogSource:
    """Follows an operator target along a jerk-limited path recomputed every tick.

    Two ways to stop: reach the target, or :meth:`brake` (ruckig's velocity interface to
    zero velocity, a jerk-limited stop wherever the path is now), after which the target
    is the point where it stopped.
    """

    name = "jog"

    def __init__(self, start_m: np.ndarray, limits: Limits, dt_s: float) -> None:
        self._otg = Ruckig(3, dt_s)
        self._limits = limits
        self._inp = _ruckig_input(np.asarray(start_m, dtype=np.float64), [limits] * 3)
        self._out = OutputParameter(3)

    @property
    def target_m(self) -> np.ndarray:
        return np.array(self._inp.target_position)

    @property
    def commanded_m(self) -> np.ndarray:
        return np.array(self._inp.current_position)

    @property
    def braking(self) -> bool:
        return self._inp.control_interface == ControlInterface.Velocity

    @property
    def at_rest(self) -> bool:
        """The jog has reached its target and stands there (no speed, no acceleration, to
        ruckig's rounding: ``AT_REST``): it holds a point, it does not move the arm."""
        inp = self._inp
        off = np.subtract(inp.current_position, inp.target_position)
        motion = np.concatenate([off, inp.current_velocity, inp.current_acceleration])
        return not self.braking and bool(np.abs(motion).max() <= AT_REST)

    @property
    def aim_m(self) -> np.ndarray:
        """Where the jog is heading: its target, or while braking where it is now."""
        return self.commanded_m if self.braking else self.target_m

    def set_target(self, target_m: np.ndarray) -> None:
        """New target (already gated); the path bends towards it from where it is now."""
        self._inp.control_interface = ControlInterface.Position
        self._inp.target_position = np.asarray(target_m, dtype=np.float64).tolist()

    def set_speed(self, per_axis_m_s: np.ndarray | None) -> None:
        """Cap the speed per axis [m/s] at most at the limits; None: the limits themselves."""
        limit = self._limits.velocity
        speed = np.full(3, limit) if per_axis_m_s is None else np.minimum(per_axis_m_s, limit)
        self._inp.max_velocity = np.maximum(speed, MIN_SPEED_M_S).tolist()

    def brake(self) -> None:
        """Stop as soon as the limits allow, where the path is now (not at the target)."""
        self._inp.control_interface = ControlInterface.Velocity
        self._inp.target_velocity = [0.0, 0.0, 0.0]
        self._inp.target_acceleration = [0.0, 0.0, 0.0]

    def next(self, dt_s: float) -> Setpoint:
        result = self._otg.update(self._inp, self._out)
        if result not in (Result.Working, Result.Finished):
            raise RuntimeError(f"ruckig could not plan the jog path: {result}")
        self._out.pass_to_input(self._inp)
        if result == Result.Finished and self.braking:  # stopped: hold here from now on
            self.set_target(self.commanded_m)
        point = np.array(self._out.new_position)
        return Setpoint(point_m=point, goal_m=point if self.braking else self.target_m)


class MoveSource:
    """One smooth point-to-point move (thesis ch. 5.2), Cartesian or in joint space.

    start, target: the tip [m] or the joints [rad], shape (3,), each axis within
    ``limits``; with a ``wrist`` the wrist angle phi is a fourth axis of the same
    time-synchronized ruckig trajectory, so the three and phi set off and arrive together
    (each setpoint then carries its ``phi_rad``). Raises GoalRejected when ruckig finds no
    path.
    """

    def __init__(
        self,
        start: np.ndarray,
        target: np.ndarray,
        limits: Limits,
        duration_s: float | None,
        joint_space: bool,
        wrist: WristAxis | None = None,
    ) -> None:
        self.name = "move-joints" if joint_space else "move"
        self.joint_space = joint_space
        self.wrist = wrist
        start = np.asarray(start, dtype=np.float64)
        target = np.asarray(target, dtype=np.float64)
        axes = [limits] * 3
        if wrist is not None:
            start = np.append(start, wrist.start_rad)
            target = np.append(target, wrist.target_rad)
            axes.append(wrist.limits)
        inp = _ruckig_input(start, axes)
        inp.target_position = target.tolist()
        self._target = target
        if duration_s is not None:
            inp.minimum_duration = duration_s
        self._trajectory = _plan(inp)
        self._t = 0.0

    @property
    def duration_s(self) -> float:
        return float(self._trajectory.duration)

    def next(self, dt_s: float) -> Setpoint:
        self._t = min(self._t + dt_s, self.duration_s)
        position, _, _ = self._trajectory.at_time(self._t)
        done = self._t >= self.duration_s
        # at the end exactly the target (ruckig's last sample may differ by a rounding)
        value = self._target.copy() if done else np.array(position)
        phi = goal = None
        if self.wrist is not None:
            phi, goal = float(value[3]), self.wrist.target_rad
        if self.joint_space:
            return Setpoint(joints_rad=value[:3], phi_rad=phi, goal_phi_rad=goal, finished=done)
        return Setpoint(point_m=value[:3], phi_rad=phi, goal_phi_rad=goal, finished=done)


def _plan(inp: InputParameter):
    from ruckig import Trajectory

    n = inp.degrees_of_freedom
    trajectory = Trajectory(n)
    result = Ruckig(n).calculate(inp, trajectory)
    if result not in (Result.Working, Result.Finished):
        raise GoalRejected(f"no smooth path to the target ({result})")
    return trajectory
