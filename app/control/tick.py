"""One control tick as functions of (state, context, ports), as the commands are.

:func:`tick` reads the joint state, records servo faults, takes a setpoint from the goal
source, passes it through the gate, solves IK on the branch nearest the command, limits the
joint step, writes the goal and checks the following error: everything the loop does
between running the queued commands and publishing the snapshot (app/control/controller.py
keeps the thread, that order and the queue). ``state`` is the control thread's
(app/control/loop_state.py); ``ctx`` the model and limits in use
(app/control/commands.py ``CommandContext``); ``ports`` the bus as the loop sees it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from app.control import commands, held_jog
from app.control.commands import CommandContext, record_fault
from app.control.contact import observe
from app.control.errors import GoalRejected
from app.control.joint_offsets import OffsetBus
from app.control.loop_state import LoopState
from app.control.safety import servo_faults
from app.control.sources import Setpoint
from app.control.state import Fault
from app.control.wrist import WristBus, next_phi
from hardware.errors import BusError

Clock = Callable[[], float]  # loop time [s]
LEVEL_GRAVITY = np.array([0.0, 0.0, -9.81])  # in the world [m/s^2] (kinematics.dynamics')


@dataclass(frozen=True)
class TickPorts:
    """The bus as the tick uses it. joint_bus: the legs (and a wrist riding along in the
    same sync read and write) through calibration's joint offsets; wrist: the wrist's view
    of that bus (None without one); external: the simulator's "motion capture" of the
    platform, ``external(at_last_read=True)`` -> (3,) [m] (None on real buses)."""

    joint_bus: OffsetBus
    wrist: WristBus | None = None
    external: Callable[..., np.ndarray] | None = None


def tick(state: LoopState, ctx: CommandContext, ports: TickPorts, now: Clock) -> None:
    """Read, record servo faults, and advance the goal source one tick (module doc)."""
    joints = state.joints if read(state, ctx, ports, now) else None
    if joints is not None and joints.faulted:
        for fault in servo_faults(ctx.servo_ids, joints.hardware_errors, now()):
            record_fault(state, fault)
    wrist = ports.wrist
    if joints is not None and wrist is not None and wrist.faulted:
        errors = (wrist.hardware_errors,)
        for fault in servo_faults((wrist.servo_id,), errors, now()):
            record_fault(state, fault)
    if joints is not None:
        _check_contact(state, ctx, ports, now)
    advance(state, ctx, ports, now)


def _check_contact(state: LoopState, ctx: CommandContext, ports: TickPorts, now: Clock) -> None:
    """This tick's contact force (app/control/contact.py); past a limit, or lost while a
    source presses, the motion stops with the joints commanded where they were measured
    (the servos stop pushing into what was hit) and the loop faults."""
    monitor = state.contact_monitor
    if monitor is None or state.joints is None:
        return
    # gravity in the base frame: turned by the drone's attitude while a source knows it
    # (a hold in the world, a press on one), else the level base's
    base = getattr(state.source, "base_pose", None)
    monitor.gravity = None if base is None else np.asarray(base.rotation).T @ LEVEL_GRAVITY
    source = state.source if commands.motion_allowed(state) else None
    reading = monitor.read(state.joints)  # every tick (~20 us: app/control/force.py)
    state.contact = reading if not state.freshness.stale else replace(reading, fresh=False)
    fault = monitor.check(state.contact, source, state.point_m, now())
    if fault is None:
        return
    # hold where measured, within the joint limits: an arm pushed past one gets no goal there
    gate = ctx.model.gate
    held = np.clip(state.joints.position_rad, gate.joint_min_rad, gate.joint_max_rad)
    write(state, ctx, ports, now, held)
    record_fault(state, fault)


def read(state: LoopState, ctx: CommandContext, ports: TickPorts, now: Clock) -> bool:
    """Read the joint state into ``state`` (the measured joints, platform, tip and the
    simulator's external measurement); False (a miss counted, a fault once too many
    failed in a row) when the read failed."""
    try:
        joints = ports.joint_bus.read_state()
    except BusError as exc:
        if state.misses.miss():
            reason = f"{state.misses.consecutive} reads failed: {exc}"
            record_fault(state, Fault("bus", reason, time_s=now(), kind="reads failed"))
        return False
    state.misses.ok()
    state.freshness.update(now(), joints, state.commanded_rad)
    state.joints = joints
    if ports.wrist is not None:
        state.wrist, state.phi_commanded_rad = ports.wrist.reading, ports.wrist.phi_rad
    gate = ctx.model.gate
    state.platform_m = ctx.model.robot.fk(joints.position_rad).points
    # the tip at the measured wrist angle (the held one without a wrist servo)
    state.point_m = gate.tip(state.platform_m, phi_measured(state))
    if ports.external is not None:  # the simulator's "motion capture" of the platform,
        external = ports.external(at_last_read=True)  # at the read's instant
        state.external_m = gate.tip(external, phi_measured(state))
    return True


def phi_measured(state: LoopState) -> float:
    """The wrist angle the tool is at [rad]: the wrist servo's reading, else (no wrist, or
    none read) the angle the loop holds the tool at."""
    wrist = state.wrist
    if wrist is not None and math.isfinite(wrist.position_rad):
        return float(wrist.position_rad)
    return state.phi_rad


def phi_commanded(state: LoopState) -> float:
    """The wrist angle [rad] of the tip's commanded points: as last written, else held."""
    return state.phi_rad if state.phi_commanded_rad is None else state.phi_commanded_rad


def advance(state: LoopState, ctx: CommandContext, ports: TickPorts, now: Clock) -> None:
    """Take this tick's setpoint from the active source and follow it (or, with none,
    settle onto a finished source's last joints and turn the wrist alone)."""
    source = state.source
    if not commands.motion_allowed(state) or state.joints is None:
        return
    if source is None:
        _settle(state, ctx, ports, now)
        _turn_wrist_alone(state, ctx, ports, now)
        return
    state.settle_rad = None  # a new source starts from the command
    held_jog.tick(state, ctx, now())  # a held jog whose heartbeat is late stops
    observe(source, state.contact, state.point_m, state.joints.position_rad)  # touch, press
    setpoint = source.next(state.dt_s)
    touch = getattr(source, "touch_result", None)
    if touch is not None:
        state.touch = touch
    state.phase, state.extra = setpoint.phase, setpoint.extra
    if setpoint.fault is not None:
        reason = f"{source.name}: {setpoint.fault}"
        record_fault(state, Fault("source", reason, time_s=now(), kind=source.name))
        return
    if setpoint.goal_m is not None:
        state.goal_m = setpoint.goal_m
    if setpoint.point_m is None and setpoint.joints_rad is None:
        state.warning = setpoint.warning  # the source asks to hold where we are
    else:
        _follow(state, ctx, ports, now, setpoint)
    if setpoint.finished and state.source is source:
        state.source = None
        state.finished_source_id = getattr(source, "source_id", None)


def _follow(
    state: LoopState, ctx: CommandContext, ports: TickPorts, now: Clock, setpoint: Setpoint
) -> None:
    gate = ctx.model.gate
    phi: float | None = None
    if setpoint.phi_rad is not None:
        try:  # a wrist goal beyond its limits is refused: nothing of this tick is written
            phi = gate.check_phi(setpoint.phi_rad)
        except GoalRejected as exc:
            state.warning = f"holding: {exc}"
            return
        # the wrist turns there this tick, and the tip's goals stay at it once the
        # source ends; its goal shown is the nominal one (a move's target)
        state.phi_rad = phi
        goal = setpoint.goal_phi_rad
        state.phi_goal_rad = phi if goal is None else goal
    if (joints := _setpoint_joints(state, ctx, setpoint)) is None:
        return
    write(state, ctx, ports, now, joints, phi)
    if setpoint.finished and not np.array_equal(state.commanded_rad, joints):
        state.settle_rad = joints  # the speed limit kept the last step short
    _check_following(state, now)


def _settle(state: LoopState, ctx: CommandContext, ports: TickPorts, now: Clock) -> None:
    """Step on to a finished source's last joints (``state.settle_rad``) at the joint
    speed limit: late ticks let a source end while the limit still held its joints
    back, and a move would otherwise stop short of its goal."""
    if state.settle_rad is None or state.commanded_rad is None:
        return
    write(state, ctx, ports, now, state.settle_rad)
    if np.array_equal(state.commanded_rad, state.settle_rad):
        state.settle_rad = None
    _check_following(state, now)


def _check_following(state: LoopState, now: Clock) -> None:
    time_s = now()
    if state.freshness.certain:  # an old state: it says nothing of how the joints follow
        fault = state.freshness.fault(time_s)
    else:
        assert state.commanded_rad is not None and state.joints is not None
        commanded, measured = state.commanded_rad, state.joints.position_rad
        if state.wrist is not None and state.phi_commanded_rad is not None:
            commanded = np.append(commanded, state.phi_commanded_rad)  # joint 4: the wrist
            measured = np.append(measured, state.wrist.position_rad)
        fault = state.following.check(time_s, commanded, measured)
    if fault is not None:
        record_fault(state, fault)


def _turn_wrist_alone(state: LoopState, ctx: CommandContext, ports: TickPorts, now: Clock) -> None:
    """No source: the legs hold their command, the wrist turns on towards its goal and is
    held to it."""
    if ports.wrist is None or state.phi_goal_rad is None or state.commanded_rad is None:
        return
    if state.phi_commanded_rad != state.phi_goal_rad:
        write(state, ctx, ports, now, state.commanded_rad)
    # checked while the goal stands (a stop clears it), not only while it turns: a short
    # turn ends before a stuck wrist's error has lasted following_error_time_s. A stale
    # state says nothing of that, and idle is no time to fault on staleness.
    if not state.freshness.certain:
        _check_following(state, now)


def _setpoint_joints(
    state: LoopState, ctx: CommandContext, setpoint: Setpoint
) -> np.ndarray | None:
    gate = ctx.model.gate
    try:
        if setpoint.joints_rad is not None:
            return gate.check_joints(setpoint.joints_rad)
        assert setpoint.point_m is not None
        phi = state.phi_rad if setpoint.phi_rad is None else setpoint.phi_rad
        point = gate.clamp_point(setpoint.point_m, phi)
        return gate.solve(point, state.reference_rad, phi)
    except GoalRejected as exc:
        state.warning = f"holding: {exc}"  # the path crossed a limit: stay put
        return None


def write(
    state: LoopState,
    ctx: CommandContext,
    ports: TickPorts,
    now: Clock,
    joints: np.ndarray,
    phi_rad: float | None = None,
) -> None:
    """Write the legs' ``joints`` (3,) [rad] within the step limit (shifted by the gravity
    offset, when on), and a wrist's goal towards ``phi_rad`` [rad] (None: towards
    ``state.phi_goal_rad``); a failed write counts as a miss."""
    gate = ctx.model.gate
    joints = gate.limit_step(joints, state.reference_rad)
    wrist = ports.wrist
    if wrist is not None:  # the wrist's goal goes out in the same sync write
        wrist.phi_rad = next_phi(state, wrist, gate.wrist_max_step_rad, phi_rad)
    servo_goal = joints
    if state.gravity is not None:
        offset = state.gravity.offset_rad(joints)
        servo_goal = joints + np.where(np.isfinite(offset), offset, 0.0)
    try:
        ports.joint_bus.write_goal(servo_goal)
    except BusError as exc:
        if state.misses.miss():
            reason = f"goal writes failing: {exc}"
            record_fault(state, Fault("bus", reason, time_s=now(), kind="writes failed"))
        return
    state.commanded_rad = joints
    if wrist is not None:
        state.phi_commanded_rad = wrist.phi_rad
    platform = ctx.model.robot.fk(joints).points
    state.commanded_point_m = gate.tip(platform, phi_commanded(state))
    state.warning = None
