"""Operator commands of the controller: goal, jog, move, torque, e-stop, reset.

Each public method checks its input in the caller's thread (the gate is pure), then queues
the state change to run in the control thread; it returns a Future with the outcome.
GoalRejected means the goal is bad (HTTP 422); MotionRefused that the robot is not in a
state to move (HTTP 409): e-stop or fault active, or torque off.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from concurrent.futures import Future
from queue import Empty
from typing import TYPE_CHECKING, Any

import numpy as np

from app.control.errors import GoalRejected, MotionRefused
from app.control.sources import GoalSource, JogSource, Limits, MoveSource
from hardware.errors import BusError

if TYPE_CHECKING:
    from app.control.controller import Controller


class CommandsMixin:
    """Command half of :class:`Controller` (split out to keep each file readable)."""

    # ---- the queue between any thread and the control thread ----
    def submit(self: Controller, command: Callable[[], Any]) -> Future:
        """Run ``command()`` in the control thread at the start of the next tick."""
        future: Future = Future()
        if not self.running:
            future.set_exception(RuntimeError("the control loop is not running"))
        else:
            self._commands.put((command, future))
        return future

    def _run_commands(self: Controller) -> list[tuple[Future, Any]]:
        """Run every queued command (control thread); their outcomes, to answer later."""
        outcomes: list[tuple[Future, Any]] = []
        while True:
            try:
                command, future = self._commands.get_nowait()
            except Empty:
                return outcomes
            if future.set_running_or_notify_cancel():
                try:
                    outcomes.append((future, command()))
                except Exception as exc:
                    outcomes.append((future, exc))

    # ---- public, any thread ----
    def set_goal(self: Controller, point: Any) -> Future:
        """Jog target, checked strictly: outside the workspace is refused with the nearest."""
        goal = self.gate.check_point(point)
        near = self.snapshot().joints_measured_rad
        self.gate.solve(goal, near if np.isfinite(near).all() else np.zeros(3))
        return self.submit(lambda: self._jog_to(goal))

    def jog(self: Controller, delta_m: Any) -> Future:
        """Relative jog step [m]; a target outside the workspace is clamped onto it."""
        delta = np.asarray(delta_m, dtype=np.float64)
        if delta.shape != (3,) or not np.isfinite(delta).all():
            raise GoalRejected(f"delta_m: expected 3 finite numbers, got {delta_m!r}")
        return self.submit(lambda: self._jog_by(delta))

    def move(
        self: Controller,
        point: Any = None,
        joints: Any = None,
        duration_s: float | None = None,
        joint_space: bool = False,
    ) -> Future:
        """Smooth move-to a point (Cartesian or joint-space path) or to joint angles."""
        if (point is None) == (joints is None):
            raise GoalRejected("give exactly one of position_m or joints_rad")
        if joints is not None:
            target = self.gate.check_joints(np.asarray(joints, dtype=np.float64))
            return self.submit(lambda: self._move(target, duration_s, True))
        goal = self.gate.check_point(point)
        near = self.snapshot().joints_measured_rad
        target = self.gate.solve(goal, near if np.isfinite(near).all() else np.zeros(3))
        if joint_space:
            return self.submit(lambda: self._move(target, duration_s, True))
        return self.submit(lambda: self._move(goal, duration_s, False))

    def run_source(
        self: Controller,
        source: GoalSource,
        expected_start_m: np.ndarray,
        tolerance_m: float = 2e-3,
    ) -> Future:
        """Hand the loop a planned source that starts at ``expected_start_m`` [m].

        The plan was checked from that point; if the robot has moved since, it is refused.
        """
        return self.submit(lambda: self._run_source(source, expected_start_m, tolerance_m))

    def stop_source(self: Controller, source: GoalSource) -> Future:
        """Stop ``source`` if it is still the active one; the robot holds where it is."""
        return self.submit(lambda: self._stop_source(source))

    def set_torque(self: Controller, enabled: bool) -> Future:
        return self.submit(lambda: self._torque_to(enabled))

    def estop(self: Controller) -> Future:
        """Stop at once and hold or release per config; nothing moves until reset."""
        if not self.running:  # no loop to queue on: act directly
            future: Future = Future()
            future.set_result(self._estop_now())
            return future
        return self.submit(self._estop_now)

    def reset(self: Controller) -> Future:
        """Clear e-stop and faults, rebooting servos that report hardware errors."""
        return self.submit(self._reset_now)

    # ---- control thread ----
    def _require_motion(self: Controller) -> None:
        if self._estopped:
            raise MotionRefused("e-stop is active: POST /api/reset first")
        if self._faults:
            raise MotionRefused(f"fault: {self._faults[0].reason}; POST /api/reset first")
        if not self._torque:
            raise MotionRefused('torque is off: POST /api/torque {"enabled": true} first')

    def _start_point(self: Controller) -> np.ndarray:
        if np.isfinite(self._commanded_point).all():
            return self._commanded_point
        return self._point

    def _jog_to(self: Controller, goal: np.ndarray) -> list[float]:
        self._require_motion()
        if not isinstance(self._source, JogSource):
            jog = self.settings.jog
            limits = Limits(jog.max_velocity_m_s, jog.max_acceleration_m_s2, jog.max_jerk_m_s3)
            self._source = JogSource(self._start_point(), limits, self.period_s)
        self._source.set_target(goal)
        self._goal = goal
        return goal.tolist()

    def _jog_by(self: Controller, delta: np.ndarray) -> list[float]:
        self._require_motion()
        base = self._goal if isinstance(self._source, JogSource) else self._start_point()
        near = self._commanded if self._commanded is not None else self._state.position_rad
        return self._jog_to(self.gate.clamp_towards(base, base + delta, near))

    def _move(self: Controller, target: np.ndarray, duration_s: float | None, joints: bool):
        self._require_motion()
        if joints:
            speed = self.settings.limits.joint_speed_rad_s
            limits = Limits(0.5 * speed, 4.0 * speed, 40.0 * speed)
            start = self._commanded if self._commanded is not None else self._state.position_rad
            self._goal = self.robot.fk(target).points
        else:
            jog = self.settings.jog
            limits = Limits(jog.max_velocity_m_s, jog.max_acceleration_m_s2, jog.max_jerk_m_s3)
            start = self._start_point()
            self._goal = target
        source = MoveSource(start, target, limits, duration_s, joint_space=joints)
        self._source = source
        return {"duration_s": source.duration_s}

    def _run_source(self: Controller, source: GoalSource, start: np.ndarray, tol: float) -> str:
        self._require_motion()
        moved = float(np.linalg.norm(self._start_point() - start))
        if math.isfinite(tol) and not moved <= tol:
            raise MotionRefused(f"the robot moved {moved * 1e3:.1f} mm since the plan; start again")
        self._source = source
        return source.name

    def _stop_source(self: Controller, source: GoalSource) -> bool:
        if self._source is not source:
            return False
        self._source = None
        return True

    def _torque_to(self: Controller, enabled: bool) -> bool:
        if enabled:
            if self._estopped or self._faults:
                self._require_motion()  # raises with the reason
            if self._state is None:
                raise MotionRefused("no joint state read yet: check the bus")
            hold = self._state.position_rad
            self.bus.write_goal(hold)  # where it is, so enabling torque moves nothing
            self.bus.torque(True)
            self._commanded, self._commanded_point = hold.copy(), self._point.copy()
        else:
            self._source = None
            self.bus.torque(False)
        self._torque = enabled
        return enabled

    def _estop_now(self: Controller) -> str:
        self._source = None
        self._estopped = True
        try:
            if self.settings.safety.estop_action == "release" or self._state is None:
                self.bus.torque(False)
                self._torque = False
            else:
                self.bus.write_goal(self._state.position_rad)
                self._commanded = self._state.position_rad.copy()
                self._commanded_point = self._point.copy()
        except BusError as exc:  # still e-stopped; say the bus did not answer
            self._warning = f"e-stop could not reach the servos: {exc}"
        return self.settings.safety.estop_action

    def _reset_now(self: Controller) -> dict:
        failing = [
            sid
            for sid, errors in zip(self.servo_ids, self._snapshot.hardware_errors, strict=True)
            if errors
        ]
        if failing:
            self.bus.reboot(failing)
            self._torque = False  # a reboot leaves torque off
        self._faults.clear()
        self._estopped = False
        self._warning = None
        self._following.reset()
        self._misses.ok()
        self._source = None
        return {"rebooted": failing}
