"""The controller: the only owner of the servo bus, ticking in its own thread.

Each tick: run queued operator commands, read the joint state, FK to the measured platform
position, take a setpoint from the active goal source, pass it through the gate, IK on the
branch nearest the current joints, limit joint speed, write the goal, check safety, then
publish an immutable Snapshot. Operator commands (HTTP handlers, the 3D scene's callbacks)
never touch the bus: they are queued and run at the start of the next tick, in this thread.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from queue import SimpleQueue
from typing import Any

import numpy as np

from app.config import Settings
from app.control.commands import CommandsMixin
from app.control.errors import GoalRejected
from app.control.gate import Gate
from app.control.safety import FollowingError, MissCounter, servo_faults
from app.control.sources import GoalSource, Setpoint
from app.control.state import Fault, Snapshot
from app.control.timing import TickClock, TimingRecorder
from hardware.bus import JointState, ServoBus
from hardware.errors import BusError

log = logging.getLogger(__name__)
Listener = Callable[[Snapshot], None]


class Controller(CommandsMixin):
    """Runs the control loop for one robot on one bus. start() / stop() from the lifespan."""

    def __init__(
        self, settings: Settings, bus: ServoBus, backend: str, backend_description: str = ""
    ) -> None:
        self.settings = settings
        self.robot = settings.robot.build()
        self.bus = bus
        self.backend = backend
        self.backend_description = backend_description or backend
        self.servo_ids = tuple(j.servo_id for j in settings.hardware.joints)
        self.period_s = 1.0 / settings.loop.rate_hz
        joints = settings.hardware.joints
        self.gate = Gate(
            self.robot,
            tuple(j.min_angle_rad for j in joints),  # type: ignore[arg-type]
            tuple(j.max_angle_rad for j in joints),  # type: ignore[arg-type]
            settings.limits.workspace_margin_m,
            settings.limits.z_max_m,
            settings.limits.min_dexterity,
            settings.limits.joint_speed_rad_s * self.period_s,
        )
        self.timing = TimingRecorder(settings.loop.rate_hz)
        self._commands: SimpleQueue[tuple[Callable[[], Any], Future]] = SimpleQueue()
        self._listeners: list[Listener] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._misses = MissCounter(settings.safety.max_missed_reads)
        self._following = FollowingError(
            settings.safety.following_error_rad, settings.safety.following_error_time_s
        )
        self._source: GoalSource | None = None
        self._faults: list[Fault] = []
        self._torque = False
        self._estopped = False
        self._warning: str | None = None
        self._state: JointState | None = None
        self._point = np.full(3, np.nan)
        self._commanded: np.ndarray | None = None
        self._commanded_point = np.full(3, np.nan)
        self._goal = np.full(3, np.nan)
        self._tick = 0
        self._phase = ""
        self._extra: dict | None = None
        self._external = getattr(bus, "measure_platform", None)
        self._external_m = np.full(3, np.nan)
        self._lateness_s = 0.0
        self._dt_s = self.period_s
        self._t0 = time.monotonic()
        self._snapshot = Snapshot()
        self.pose_status: Callable[[], dict] | None = None  # set by the world service

    # ---- lifecycle ----
    def start(self) -> None:
        """Read the robot once (so status is meaningful at once) and start ticking."""
        self._read()
        self._publish()
        self._thread = threading.Thread(target=self._run, name="deltadash-control", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop ticking; relax the servos if the config says so."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        self._source = None  # ruckig objects must not outlive the interpreter's shutdown
        if self.settings.safety.torque_off_on_exit and self._torque:
            try:
                self.bus.torque(False)
            except BusError as exc:
                log.warning("torque off at exit failed: %s", exc)

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def snapshot(self) -> Snapshot:
        """The state after the last tick (immutable; safe from any thread)."""
        return self._snapshot

    def add_listener(self, listener: Listener) -> None:
        """Call ``listener(snapshot)`` after every tick, in the control thread: keep it fast."""
        self._listeners.append(listener)

    def remove_listener(self, listener: Listener) -> None:
        if listener in self._listeners:
            self._listeners.remove(listener)

    # ---- the loop ----
    def _run(self) -> None:
        clock = TickClock(self.settings.loop.rate_hz, self.settings.loop.spin_s)
        previous: float | None = None
        while not self._stop.is_set():
            deadline, lateness = clock.wait_next()
            # sources advance by the scheduled time elapsed, which includes skipped slots
            self._dt_s = self.period_s if previous is None else deadline - previous
            previous = deadline
            self._lateness_s = lateness
            started = time.perf_counter()
            try:
                self._step()
            except Exception as exc:  # a bug must stop motion, not the loop
                log.exception("control tick failed")
                self._fault(Fault("loop", f"internal error: {exc!r}", time_s=self._now()))
            self.timing.record(deadline, lateness, time.perf_counter() - started)

    def _step(self) -> None:
        self._tick += 1
        outcomes = self._run_commands()
        try:
            if self._read() and self._state is not None and self._state.faulted:
                now = self._now()
                for fault in servo_faults(self.servo_ids, self._state.hardware_errors, now):
                    self._fault(fault)
            self._advance()
            self._publish()
        finally:
            for future, outcome in outcomes:  # answered once the snapshot shows the change
                if isinstance(outcome, BaseException):
                    future.set_exception(outcome)
                else:
                    future.set_result(outcome)

    def _read(self) -> bool:
        try:
            state = self.bus.read_state()
        except BusError as exc:
            if self._misses.miss():
                self._fault(
                    Fault(
                        "bus", f"{self._misses.consecutive} reads failed: {exc}", time_s=self._now()
                    )
                )
            return False
        self._misses.ok()
        self._state = state
        self._point = self.robot.fk(state.position_rad).points
        if self._external is not None:  # the simulator's "motion capture" of the platform,
            self._external_m = self._external(at_last_read=True)  # at the read's instant
        return True

    def _advance(self) -> None:
        if self._source is None or not self._motion_allowed() or self._state is None:
            return
        source = self._source
        setpoint = source.next(self._dt_s)
        self._phase, self._extra = setpoint.phase, setpoint.extra
        if setpoint.fault is not None:
            self._fault(Fault("source", f"{source.name}: {setpoint.fault}", time_s=self._now()))
            return
        if setpoint.goal_m is not None:
            self._goal = setpoint.goal_m
        if setpoint.point_m is None and setpoint.joints_rad is None:
            self._warning = setpoint.warning  # the source asks to hold where we are
        else:
            self._follow(setpoint)
        if setpoint.finished and self._source is source:
            self._source = None

    def _follow(self, setpoint: Setpoint) -> None:
        joints = self._setpoint_joints(setpoint)
        if joints is None:
            return
        self._write(joints, setpoint)
        fault = self._following.check(self._now(), self._commanded, self._state.position_rad)
        if fault is not None:
            self._fault(fault)

    def _setpoint_joints(self, setpoint: Setpoint) -> np.ndarray | None:
        near = self._commanded if self._commanded is not None else self._state.position_rad
        try:
            if setpoint.joints_rad is not None:
                return self.gate.check_joints(setpoint.joints_rad)
            return self.gate.solve(self.gate.clamp_point(setpoint.point_m), near)
        except GoalRejected as exc:
            self._warning = f"holding: {exc}"  # the path crossed a limit: stay put
            return None

    def _write(self, joints: np.ndarray, setpoint: Setpoint) -> None:
        previous = self._commanded if self._commanded is not None else self._state.position_rad
        joints = self.gate.limit_step(joints, previous)
        try:
            self.bus.write_goal(joints)
        except BusError as exc:
            if self._misses.miss():
                self._fault(Fault("bus", f"goal writes failing: {exc}", time_s=self._now()))
            return
        self._commanded = joints
        self._commanded_point = self.robot.fk(joints).points
        self._warning = None

    def _motion_allowed(self) -> bool:
        return self._torque and not self._estopped and not self._faults

    def _fault(self, fault: Fault) -> None:
        """Record a fault (once per reason) and stop: hold where the robot is."""
        if any(f.source == fault.source and f.reason == fault.reason for f in self._faults):
            return
        log.error("fault: %s", fault.reason)
        self._faults.append(fault)
        self._source = None

    def _now(self) -> float:
        return time.monotonic() - self._t0

    def _publish(self) -> None:
        state = self._state
        nan3 = np.full(3, np.nan)
        commanded = self._commanded if self._commanded is not None else nan3
        self._snapshot = Snapshot(
            time_s=self._now(),
            tick=self._tick,
            mode=self.mode,
            torque=self._torque,
            estopped=self._estopped,
            faults=tuple(self._faults),
            warning=self._warning,
            joints_measured_rad=state.position_rad if state else nan3,
            point_measured_m=self._point,
            joints_commanded_rad=commanded,
            point_commanded_m=self._commanded_point,
            goal_m=self._goal,
            velocity_rad_s=state.velocity_rad_s if state else nan3,
            current_a=state.current_a if state else nan3,
            voltage_v=state.voltage_v if state else nan3,
            temperature_c=state.temperature_c if state else nan3,
            moving=tuple(bool(m) for m in state.moving) if state else (False,) * 3,
            hardware_errors=state.hardware_errors if state else ((),) * 3,
            missed_reads=self._misses.total,
            phase=self._phase if self._source else "",
            lateness_ms=self._lateness_s * 1e3,
            extra=self._extra if self._source else None,
            external_m=self._external_m,
        )
        for listener in tuple(self._listeners):  # a listener may remove itself
            listener(self._snapshot)

    @property
    def measured_point(self) -> np.ndarray:
        """This tick's measured platform position (call from the control thread)."""
        return self._point

    @property
    def current_source(self) -> GoalSource | None:
        """The active goal source (read it from the control thread, e.g. in a listener)."""
        return self._source

    @property
    def mode(self) -> str:
        if self._estopped:
            return "estop"
        if self._faults:
            return "fault"
        return self._source.name if self._source is not None else "idle"
