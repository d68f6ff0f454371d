"""The controller: the only owner of the servo bus, ticking in its own thread.

Each tick: run queued operator commands, read the joint state, FK to the measured platform
position and its tool tip, take a (tip) setpoint from the active goal source, pass it
through the gate (which checks the platform point the tip implies), IK on the branch
nearest the current joints, limit joint speed, write the goal, check safety, then publish
an immutable Snapshot. Operator commands (HTTP handlers, the 3D scene's callbacks)
never touch the bus: they are queued and run at the start of the next tick, in this thread.
The tick's work between the commands and the publish is app/control/tick.py's, a function of
the loop's state, the command context and the bus; this class keeps the thread, that order
and the queue.
"""

from __future__ import annotations

import atexit
import dataclasses
import logging
import math
import threading
import time
import uuid
import weakref
from collections.abc import Callable
from concurrent.futures import Future
from queue import Empty, SimpleQueue
from typing import Any

import numpy as np

from app.config import Settings
from app.control import commands, contact_commands, held_jog
from app.control.commands import CommandContext, record_fault
from app.control.contact import ContactMonitor
from app.control.errors import GoalRejected, MotionRefused
from app.control.force import ForceEstimator, force_estimator
from app.control.gate import Gate
from app.control.gravity import GravityOffset, gravity_offset, loop_stiffness_nm_rad
from app.control.joint_offsets import OffsetBus, set_offsets
from app.control.loop_state import LoopState
from app.control.model import Robot, RobotModel, dynamics_robot
from app.control.owner import MotionOwner
from app.control.servo_current import DEFAULT_GOAL_CURRENT_A, DEFAULT_MODE
from app.control.servo_current import apply as apply_servo_current
from app.control.servo_current import check as check_servo_current
from app.control.sources import GoalSource, JogSource
from app.control.state import Fault, RobotInfo, Snapshot
from app.control.tick import TickPorts, phi_commanded, phi_measured, read, tick
from app.control.timing import TickClock, TimingRecorder
from app.control.wrist import WristBus, turn_to
from hardware.bus import BusStats, PositionGains, ServoBus, SimulatedBus
from hardware.errors import BusError
from kinematics import RotaryDelta

log = logging.getLogger(__name__)
Listener = Callable[[Snapshot], None]


# Controllers whose thread ticks. The tick calls into native code (MuJoCo on the twin,
# ruckig); a daemon thread still in it when the interpreter finalizes crashes the process
# after its work is done ("terminate called without an active exception"), so a loop not
# stopped by its owner is stopped at exit, before finalization.
_RUNNING: weakref.WeakSet[Controller] = weakref.WeakSet()


@atexit.register
def _stop_all() -> None:
    for controller in list(_RUNNING):
        controller.halt()


class Controller:
    """Runs the control loop for one robot on one bus. start() / stop() from the lifespan.

    ``state`` belongs to the control thread (the tick and the queued commands). The public
    methods check their input in the caller's thread (the gate is pure) and queue the change;
    each returns a Future with the outcome, answered once the snapshot shows the change.
    """

    def __init__(
        self,
        settings: Settings,
        bus: ServoBus,
        backend: str,
        backend_description: str = "",
        clock: Callable[[], float] = time.monotonic,
        tick_clock: TickClock | None = None,
        thread_setup: Callable[[], Any] | None = None,
    ) -> None:
        self.settings = settings
        # the robot model and the limits; replaced whole by use_model (app/control/model.py)
        self._ctx = CommandContext.from_settings(settings)
        self.servo_ids, self.period_s = self._ctx.servo_ids, self._ctx.period_s
        self.bus, self.backend = bus, backend
        # with a wrist the loop drives the legs through WristBus, the wrist riding along in
        # the same sync read and write (app/control/wrist.py); ``bus`` stays the whole bus
        wrist = settings.wrist
        self.wrist = WristBus(bus, wrist.servo_id) if wrist.enabled else None
        self.servos: ServoBus = self.wrist if self.wrist is not None else bus
        # joint positions read and goals written through calibration's joint offsets
        self.joint_bus = OffsetBus(self.servos)
        self.backend_description = backend_description or backend
        self.boot = uuid.uuid4().hex[:12]  # this loop's id, in every snapshot
        wrist_id = wrist.servo_id if wrist.enabled else None
        info = RobotInfo(
            backend, self.backend_description, tuple(self.servo_ids), self.boot, wrist_id
        )
        self.state = LoopState.initial(settings.safety, self.period_s, info)
        # the servos' factory mode and power-on Goal Current until start() writes the config's
        self.state.servo_mode, self.state.goal_current_a = DEFAULT_MODE, DEFAULT_GOAL_CURRENT_A
        # [control] gravity_compensation: servo goals shifted by the predicted sag (the
        # loop's commanded joints stay the goal's, so status and following errors see it);
        # unset: on where the bus carries a load (the twin, real servos; `carries_load`)
        if settings.gravity_on(getattr(bus, "carries_load", False)):
            self.state.gravity = gravity_offset(
                dynamics_robot(self.robot),
                settings.control.payload_kg,
                wrist=settings.wrist.enabled,
            )
        # [contact]: the tip's force each tick, from the currents of servos that carry the
        # arm (app/control/contact.py); its limits hold even without an estimate
        self.state.contact_monitor = ContactMonitor(self._force_estimator(bus), settings.contact)
        self._commands: SimpleQueue[tuple[Callable[[], Any], Future]] = SimpleQueue()
        # who may move the robot: a procedure (calibration, tuning) claims it while it runs
        # and every motion command below asks it (app/control/owner.py)
        self.owner = MotionOwner()
        self._listeners: list[Listener] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        # what the tick reads and writes: the legs through the joint offsets, the wrist,
        # and the simulator's "motion capture" of the platform (real buses have none)
        external = bus.measure_platform if isinstance(bus, SimulatedBus) else None
        self._ports = TickPorts(self.joint_bus, self.wrist, external)
        self._clock = clock  # loop time [s]; tests step a controller on a fake one
        # paces the thread; None: real time at loop.rate_hz (tests may give a virtual one)
        self._tick_clock = tick_clock
        self._t0 = clock()
        # run first in the loop's thread (a robot node's real-time scheduling: what it
        # got is kept in ``thread_setup_result``)
        self._thread_setup = thread_setup
        self.thread_setup_result: Any = None
        self._snapshot = self.state.snapshot(0.0, self._bus_stats())

    def _force_estimator(self, bus: ServoBus) -> ForceEstimator | None:
        """The estimator the loop uses: None when [contact] estimate is off, the servos
        carry no load (the emulator: their currents say nothing of a force) or the robot
        has no dynamics model (a linear Delta)."""
        settings = self.settings
        if not settings.contact.estimate or not getattr(bus, "carries_load", False):
            return None
        robot = dynamics_robot(self.robot)
        if not isinstance(robot, RotaryDelta):
            return None
        return force_estimator(robot, settings.control.payload_kg, wrist=settings.wrist.enabled)

    # ---- lifecycle ----
    def start(self) -> None:
        """Write the config's position gains, when a leg has some (the others get the
        factory's), read the robot once (so status is meaningful at once) and start
        ticking."""
        legs = self.settings.hardware.joints
        if any(j.gains is not None for j in legs):
            self._use_gains(
                [j.gains.position_gains() if j.gains else PositionGains() for j in legs]
            )
        # [hardware] operating_mode / goal_current_a, when not the servos' factory state:
        # the mode is an EEPROM item, so torque goes off first (app/control/servo_current.py)
        hardware = self.settings.hardware
        mode, currents = hardware.operating_mode, hardware.goal_currents_a()
        if (mode, currents) != (DEFAULT_MODE, DEFAULT_GOAL_CURRENT_A):
            self.servos.torque(False)
            self.state.torque = False
            apply_servo_current(self.state, self.servos, mode, currents)
        read(self.state, self._ctx, self._ports, self._now)
        self._publish()
        self._thread = threading.Thread(target=self._run, name="deltadash-control", daemon=True)
        self._thread.start()
        _RUNNING.add(self)

    def halt(self) -> None:
        """Stop ticking and wait for the thread (no torque change: see stop())."""
        self._stop.set()
        if self._tick_clock is not None:
            self._tick_clock.release()  # a simulated clock waiting to be driven lets go
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        _RUNNING.discard(self)
        self.state.source = None  # ruckig objects must not outlive the interpreter's shutdown

    def stop(self) -> str | None:
        """Stop ticking; relax the servos if the config says so (safety.torque_off_on_exit).

        Returns None when the robot was left as the config says, else why not ("torque off
        at exit failed: ..."), so a command line can exit non-zero; the server logs it.
        """
        self.halt()
        if self.settings.safety.torque_off_on_exit and self.state.torque:
            try:
                self.servos.torque(False)
            except BusError as exc:
                log.warning("torque off at exit failed: %s", exc)
                return f"torque off at exit failed: {exc}"
        return None

    # ---- the robot model: one owner, read when used (app/control/model.py) ----
    @property
    def ctx(self) -> CommandContext:
        """What commands read: the model in use and the limits (replaced, never changed)."""
        return self._ctx

    @property
    def model(self) -> RobotModel:
        """The robot model in use: its gate, robot, version and origin. Read it once where
        the robot and the gate must agree."""
        return self._ctx.model

    @property
    def robot(self) -> Robot:
        """The robot's kinematics in use (the model's)."""
        return self._ctx.model.robot

    @property
    def gate(self) -> Gate:
        """The gate in use (the model's): every goal passes it."""
        return self._ctx.model.gate

    def _checked(self, model: RobotModel) -> CommandContext:
        """The context, in the control thread, if ``model`` (what a goal was checked
        against, in the caller's thread) is still the one in use; else MotionRefused."""
        ctx = self._ctx
        if ctx.model is not model:
            raise MotionRefused(
                f"the robot model changed since this was checked ({ctx.model.origin} in "
                f"use now): send it again"
            )
        return ctx

    def thread_native_id(self) -> int | None:
        """The loop thread's kernel thread id (None before it starts)."""
        return None if self._thread is None else self._thread.native_id

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

    # ---- commands, from any thread ----
    def submit(self, command: Callable[[], Any]) -> Future:
        """Run ``command()`` in the control thread at the start of the next tick."""
        future: Future = Future()
        if not self.running:
            future.set_exception(RuntimeError("the control loop is not running"))
        else:
            self._commands.put((command, future))
            if self._tick_clock is not None:
                self._tick_clock.wake()  # a simulated clock runs a tick for it
        return future

    def submit_motion(self, command: Callable[[], Any]) -> Future:
        """:meth:`submit` for a command that moves the robot (or changes how it moves):
        MotionRefused, in the caller's thread, while a procedure holds the robot and the
        caller is not its thread (app/control/owner.py)."""
        with self.owner.permit():
            return self.submit(command)

    def set_goal(self, point: Any, phi_rad: float = 0.0) -> Future:
        """Jog target: the tool tip [m] at wrist angle ``phi_rad`` [rad], checked strictly
        (a tip whose platform point is outside the workspace is refused with the nearest)."""
        model = self.model
        goal, phi = commands.check_goal(model.gate, point, phi_rad, self._near_measured())
        return self.submit_motion(
            lambda: commands.jog_to(self.state, self._checked(model), goal, phi_rad=phi)
        )

    def jog(self, delta_m: Any, speed_m_s: float | None = None) -> Future:
        """Relative jog step [m] from what the loop commands when the step runs (not from a
        goal the caller saw); a target outside the workspace is clamped onto it.
        ``speed_m_s`` caps the speed per axis (None: the configured jog limit)."""
        delta = commands.check_vector(delta_m, "delta_m")
        if speed_m_s is not None and not (math.isfinite(speed_m_s) and speed_m_s > 0):
            raise GoalRejected(f"speed_m_s: expected a positive number, got {speed_m_s!r}")
        return self.submit_motion(lambda: commands.jog_by(self.state, self.ctx, delta, speed_m_s))

    def hold_jog(self, velocity_m_s: Any) -> Future:
        """Start or renew a held jog at ``velocity_m_s`` [m/s] (zero stops it): it moves
        only while these calls keep coming; the loop stops it ``jog.hold_timeout_s`` after
        the last one (app/control/held_jog.py)."""
        velocity = commands.check_vector(velocity_m_s, "velocity_m_s")
        return self.submit_motion(
            lambda: held_jog.hold_jog(self.state, self.ctx, velocity, self._now())
        )

    def move(
        self,
        point: Any = None,
        joints: Any = None,
        duration_s: float | None = None,
        joint_space: bool = False,
        phi_rad: float = 0.0,
    ) -> Future:
        """Smooth move-to a tip [m] at ``phi_rad`` (Cartesian or joint-space path) or to
        joint angles."""
        model = self.model
        target, joint_space = commands.check_move(
            model.gate, point, joints, joint_space, self._near_measured(), phi_rad
        )
        phi = float(phi_rad)  # checked by check_move
        return self.submit_motion(
            lambda: commands.move(
                self.state, self._checked(model), target, duration_s, joint_space, phi
            )
        )

    def run_source(
        self,
        source: GoalSource,
        expected_start_m: np.ndarray,
        tolerance_m: float = 2e-3,
        model: RobotModel | None = None,
    ) -> Future:
        """Hand the loop a planned source that starts at ``expected_start_m`` [m].

        The plan was checked from that point, against ``model`` (None: the one in use when
        it starts); if the robot has moved since, or another model is in use, it is refused.
        """

        def start() -> str:
            if model is not None:
                self._checked(model)
            return commands.run_source(self.state, source, expected_start_m, tolerance_m)

        return self.submit_motion(start)

    def stop_source(self, source: GoalSource) -> Future:
        """Stop ``source`` if it is still the active one; the robot holds where it is."""
        return self.submit(lambda: commands.stop_source(self.state, source))

    def stop_any(self) -> Future:
        """Stop whatever source is active (the robot holds where it is commanded): an
        aborted procedure's motion. The Future holds whether one was running."""

        def stop() -> bool:
            source = self.state.source
            return source is not None and commands.stop_source(self.state, source)

        return self.submit(stop)

    def touch(self, direction: Any, **values: Any) -> Future:
        """Start a touch (app/control/contact_commands.py ``touch``: ``speed_m_s``,
        ``force_n``, ``max_travel_m``, ``retract_m``); the Future holds its source id and
        ends; errors name the field."""
        contact = self.settings.contact
        return self.submit_motion(
            lambda: contact_commands.touch(self.state, self.ctx, contact, direction, **values)
        )

    def press(
        self,
        direction: Any,
        force_n: Any,
        inner: GoalSource | None = None,
        frame: str = "base",
        duration_s: Any = None,
    ) -> Future:
        """Start a compliant press (app/control/contact_commands.py ``press``)."""
        contact = self.settings.contact
        return self.submit_motion(
            lambda: contact_commands.press(
                self.state, self.ctx, contact, direction, force_n, inner, frame, duration_s
            )
        )

    def set_torque(self, enabled: bool) -> Future:
        return self.submit(
            lambda: commands.torque_to(self.state, self.ctx, self.joint_bus, enabled)
        )

    def estop(self) -> Future:
        """Stop at once and hold or release per config; nothing moves until reset."""
        if not self.running:  # no loop to queue on: act directly
            future: Future = Future()
            future.set_result(commands.estop_now(self.state, self.ctx, self.joint_bus))
            return future
        return self.submit(lambda: commands.estop_now(self.state, self.ctx, self.joint_bus))

    def reset(self) -> Future:
        """Clear e-stop and faults, rebooting servos that report hardware errors."""
        return self.submit(self._reset_now)

    def _reset_now(self) -> dict:
        """Reset (commands.reset_now), and reboot a wrist that reports a hardware error."""
        wrist_failing = self.wrist is not None and self.wrist.faulted
        outcome = commands.reset_now(self.state, self.ctx, self.joint_bus)
        if self.wrist is not None and wrist_failing:
            self.wrist.reboot([self.wrist.servo_id])
            self.state.torque = False  # a reboot leaves torque off
            outcome = {"rebooted": [*outcome["rebooted"], self.wrist.servo_id]}
        return outcome

    def turn_wrist(self, phi_rad: Any) -> Future:
        """Turn the wrist to ``phi_rad`` [rad] at its speed limit; GoalRejected (here, in
        the caller's thread) outside the wrist's limits or without a wrist; MotionRefused
        (in the Future) when the robot may not move. The hook for goals with a heading."""
        phi = self.gate.check_phi(phi_rad)
        return self.submit_motion(lambda: turn_to(self.state, phi))

    def set_joint_offsets(self, offsets_rad: Any) -> Future:
        """Joint offsets [rad] (3,) from calibration, added to every joint read from now on
        (app/control/joint_offsets.py); refused while a motion runs."""
        return self.submit_motion(
            lambda: set_offsets(
                self.state,
                self.robot,
                self.joint_bus,
                offsets_rad,
                self._tip_measured,
                self._tip_commanded,
            )
        )

    def use_model(self, robot: Robot, offsets_rad: Any, origin: str) -> Future:
        """The robot's kinematics from now on (a geometry calibration's apply), with joint
        offsets ``offsets_rad`` [rad] (3,) in place of those in use. The Future holds the
        RobotModel now in use.

        Nothing moves: the servos keep their goal ticks, and what the loop read and
        commanded is recomputed in the new model (joints shifted by the offsets' change,
        points by the new FK), so the held goal is the new model's point of the same
        joints. The next motion starts from the measured position. Refused while a motion
        runs, or a procedure holds the robot (MotionRefused in the Future, nothing changed).
        The new gate is built here, in the caller's thread: its first workspace projection
        takes tens to hundreds of ms, which the tick must not wait for.
        """
        current = self.model
        new = current.replaced(robot, origin)
        offsets = np.array(offsets_rad, dtype=np.float64)

        def swap() -> RobotModel:
            if self._ctx.model is not current:
                raise MotionRefused(
                    f"the robot model changed meanwhile ({self._ctx.model.origin}): apply again"
                )
            # the offsets first (refused while a motion runs, before anything changes),
            # with the new robot's FK for what the loop read and commands
            set_offsets(
                self.state, robot, self.joint_bus, offsets, self._tip_measured, self._tip_commanded
            )
            self._ctx = dataclasses.replace(self._ctx, model=new)
            if (gravity := self.state.gravity) is not None:
                self.state.gravity = dataclasses.replace(gravity, robot=dynamics_robot(robot))
            monitor = self.state.contact_monitor  # the force estimate: the new geometry
            if monitor is not None and isinstance(monitor.estimator, ForceEstimator):
                rotary = dynamics_robot(robot)
                if isinstance(rotary, RotaryDelta):
                    monitor.estimator = monitor.estimator.with_robot(rotary)
            self.state.notice = f"robot model from {origin}; " + (self.state.notice or "")
            return new

        return self.submit_motion(swap)

    def _tip_commanded(self, platform: np.ndarray) -> np.ndarray:
        """The tool tip [m] of a platform point at the commanded wrist angle."""
        return self.gate.tip(platform, phi_commanded(self.state))

    def _tip_measured(self, platform: np.ndarray) -> np.ndarray:
        """The tool tip [m] of a platform point at the measured wrist angle."""
        return self.gate.tip(platform, phi_measured(self.state))

    def set_gains(self, gains: dict[int, PositionGains]) -> Future:
        """Position gains per leg servo id (app/tuning), and optionally the wrist's servo
        id's (the servo panel), written to the servos in the control thread; refused while
        a motion runs (MotionRefused in the Future) and for ids that are not the legs' or
        the wrist's (ValueError, at once). The Future holds the gains now in use
        (`gains`; the wrist's too where it was given)."""
        wrist_id = self.wrist.servo_id if self.wrist is not None else None
        wrist_gains = gains.get(wrist_id) if wrist_id is not None else None
        legs = {sid: g for sid, g in gains.items() if sid != wrist_id or wrist_gains is None}
        ordered = commands.ordered_gains(legs, tuple(self.servo_ids))

        def write() -> dict[int, PositionGains]:
            if (moving := self._moving()) is not None:
                raise MotionRefused(f"a {moving} is running: gains change only while the arm rests")
            if wrist_gains is not None and self.wrist is not None:
                self.wrist.wrist_gains = wrist_gains  # written with the legs' below
            self._use_gains(ordered)
            self.state.notice = "position gains changed"
            written = dict(zip(self.servo_ids, ordered, strict=True))
            return written if wrist_gains is None else {**written, wrist_id: wrist_gains}

        return self.submit_motion(write)

    def set_servo_current(self, mode: str, currents_a: Any) -> Future:
        """The legs' servos' operating mode ("position" | "current_based_position") and
        Goal Current per leg [A] (3,), written in the control thread
        (app/control/servo_current.py). Refused at once with ValueError naming the field
        (an unknown mode, a current not > 0 and <= 3.209 A); in the Future with
        TorqueOnError (a MotionRefused) while torque is on, MotionRefused while a motion
        runs, and what the bus raises. The Future holds what is now in use:
        {"operating_mode": str, "goal_current_a": [A] (3,)}."""
        currents = check_servo_current(mode, currents_a)

        def write() -> dict[str, Any]:
            if (moving := self._moving()) is not None:
                raise MotionRefused(f"a {moving} is running: the servo mode changes at rest")
            apply_servo_current(self.state, self.servos, mode, currents)
            self.state.notice = f"servo mode {mode}, goal current {list(currents)} A"
            return {
                "operating_mode": self.state.servo_mode,
                "goal_current_a": [float(c) for c in self.state.goal_current_a],
            }

        return self.submit_motion(write)

    def read_gains(self) -> Future:
        """The legs' position gains as their servos hold them (``ServoBus.read_gains``:
        five registers per servo, read in the control thread between ticks, so the read
        holds one tick back by its bus transactions); refused while a motion runs
        (MotionRefused in the Future): a run's record would show the late tick. The
        Future holds them per leg servo id, and the wrist's servo id's with a wrist."""

        def read() -> dict[int, PositionGains]:
            if (moving := self._moving()) is not None:
                raise MotionRefused(
                    f"a {moving} is running: the servos' gains are read only while the arm rests"
                )
            read = dict(zip(self.servo_ids, self.servos.read_gains(), strict=True))
            if self.wrist is not None and self.wrist.wrist_gains_read is not None:
                read[self.wrist.servo_id] = self.wrist.wrist_gains_read  # read with the legs'
            return read

        return self.submit(read)

    def _moving(self) -> str | None:
        """What moves the arm now (the control thread's view): the active source's name;
        None at rest: no source, or a goal's jog standing at its target (it holds a point)
        with no held jog going."""
        source = self.state.source
        if source is None:
            return None
        held = self.state.hold_velocity_m_s is not None
        if isinstance(source, JogSource) and source.at_rest and not held:
            return None
        return source.name

    def _use_gains(self, ordered: list[PositionGains]) -> None:
        """Write the legs' gains (joint order) and use them (the gravity offset's stiffness
        depends on them); the control thread's, or start's before it runs."""
        self.servos.set_gains(ordered)
        state = self.state
        state.gains = tuple(ordered)
        if state.gravity is not None:  # the sag depends on the loop's stiffness
            stiffness = loop_stiffness_nm_rad(ordered)
            state.gravity = dataclasses.replace(state.gravity, stiffness_nm_rad=stiffness)

    @property
    def gains(self) -> dict[int, PositionGains]:
        """The position gains in use per leg servo id, as of the last snapshot: the
        factory's (PositionGains()) until `set_gains` writes others."""
        return dict(zip(self.servo_ids, self._snapshot.gains, strict=True))

    @property
    def gravity(self) -> GravityOffset | None:
        """The gravity offset in use (None: compensation off); read it from the control
        thread, or on a stopped loop."""
        return self.state.gravity

    @property
    def timing(self) -> TimingRecorder:
        """Every tick's timing (written by the control thread; its figures reach other
        threads in the snapshot's ``loop_total`` / ``loop_window``)."""
        return self.state.recorder

    @property
    def joint_offsets_rad(self) -> np.ndarray:
        """The joint offsets in use [rad], (3,): zeros until a calibration is applied."""
        return self.joint_bus.offsets_rad.copy()

    def _near_measured(self) -> np.ndarray:
        near = self.snapshot().joints_measured_rad
        return near if np.isfinite(near).all() else np.zeros(3)

    # ---- the loop (control thread) ----
    def _run(self) -> None:
        if self._thread_setup is not None:
            self.thread_setup_result = self._thread_setup()
        loop = self.settings.loop
        clock = self._tick_clock or TickClock(loop.rate_hz, loop.spin_s)
        previous: float | None = None
        while not self._stop.is_set():
            deadline, lateness = clock.wait_next()
            # sources advance by the scheduled time elapsed, which includes skipped slots
            self.state.dt_s = self.period_s if previous is None else deadline - previous
            previous, self.state.lateness_s = deadline, lateness
            self.state.timing = clock.last
            started = clock.now()
            try:
                self.step()
            except Exception as exc:  # a bug must stop motion, not the loop
                log.exception("control tick failed")
                fault = Fault(
                    "loop", f"internal error: {exc!r}", time_s=self._now(), kind=type(exc).__name__
                )
                record_fault(self.state, fault)
            clock.end_tick()
            self.state.recorder.record(deadline, lateness, clock.now() - started)

    def step(self) -> None:
        """One tick (the thread calls it each period; tests may call it on an unstarted one)."""
        self.state.tick += 1
        outcomes = self._run_commands()
        try:
            tick(self.state, self._ctx, self._ports, self._now)  # the commands' context
            self._publish()
        finally:
            for future, outcome in outcomes:  # answered once the snapshot shows the change
                if isinstance(outcome, BaseException):
                    future.set_exception(outcome)
                else:
                    future.set_result(outcome)

    def _run_commands(self) -> list[tuple[Future, Any]]:
        """Run every queued command; their outcomes, to answer after this tick's publish."""
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

    def _bus_stats(self) -> BusStats | None:
        """The bus's counters (``ServoBus.stats``, which never raises); None from a test's
        fake bus that keeps none."""
        return getattr(self.bus, "stats", None)

    def _now(self) -> float:
        return self._clock() - self._t0

    def _publish(self) -> None:
        self._snapshot = self.state.snapshot(self._now(), self._bus_stats())
        for listener in tuple(self._listeners):  # a listener may remove itself
            listener(self._snapshot)

    # ---- read from the control thread (e.g. in a listener) ----
    @property
    def measured_point(self) -> np.ndarray:
        """This tick's measured tool tip (call from the control thread)."""
        return self.state.point_m

    @property
    def measured_phi(self) -> float:
        """This tick's wrist angle [rad]: read, else the one the loop holds the tool at (0
        without a wrist) (call from the control thread)."""
        return phi_measured(self.state)

    @property
    def current_source(self) -> GoalSource | None:
        """The active goal source (read it from the control thread, e.g. in a listener)."""
        return self.state.source

    @property
    def mode(self) -> str:
        return self.state.mode
