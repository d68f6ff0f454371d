"""Operator commands: goal, jog, move, run, torque, e-stop, reset, as state transitions.

Each command is a plain function of the loop's state record (app/control/loop_state.py), a
read-only context (gate, limits, servo ids) and, where it talks to the servos, the bus. The
controller runs them in the control thread only, between ticks (app/control/controller.py);
tests call them directly. MotionRefused means the robot is not in a state to move (e-stop
or fault active, torque off; HTTP 409) and GoalRejected that the goal is bad (HTTP 422):
either is raised before the state changes.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from app.config import Settings
from app.control.errors import GoalRejected, MotionRefused
from app.control.gate import Gate
from app.control.loop_state import LoopState
from app.control.model import Robot, RobotModel
from app.control.sources import GoalSource, JogSource, Limits, MoveSource, WristAxis
from app.control.state import Fault
from hardware.bus import ServoBus
from hardware.errors import BusError

log = logging.getLogger(__name__)
MAX_FAULT_CAUSES = 20  # distinct causes kept in the fault list; older ones are dropped


@dataclass(frozen=True)
class CommandContext:
    """What commands read and never change: the robot model (its gate) and the configured
    limits. The controller replaces the whole context when a calibration changes the model
    (app/control/model.py); a command reads the one it was handed.

    jog_limits: per-axis Cartesian limits of jogs and Cartesian moves [m/s, m/s^2, m/s^3];
    joint_speed_rad_s: the joint speed limit that joint-space moves are scaled from;
    estop_action: "hold" (hold position with torque on) or "release" (torque off);
    hold_timeout_s: a held jog stops this long after its last heartbeat [s];
    torque_on_slack_rad: how far past a joint limit a relaxed arm may rest and still be
        taken back inside by torque on [rad];
    wrist_limits: the wrist's limits as a move's fourth axis [rad/s, rad/s^2, rad/s^3]
        (None: no wrist).
    """

    model: RobotModel
    servo_ids: tuple[int, ...]
    period_s: float
    jog_limits: Limits
    joint_speed_rad_s: float
    estop_action: Literal["hold", "release"]
    hold_timeout_s: float = 0.15
    torque_on_slack_rad: float = 0.2
    wrist_limits: Limits | None = None

    @property
    def robot(self) -> Robot:
        """The robot's kinematics (the model's)."""
        return self.model.robot

    @property
    def gate(self) -> Gate:
        """The gate every goal passes (the model's)."""
        return self.model.gate

    @classmethod
    def from_settings(cls, settings: Settings) -> CommandContext:
        robot = settings.robot.build()
        joints = settings.hardware.joints
        period_s = 1.0 / settings.loop.rate_hz
        gate = Gate(
            robot,
            tuple(j.min_angle_rad for j in joints),  # type: ignore[arg-type]
            tuple(j.max_angle_rad for j in joints),  # type: ignore[arg-type]
            settings.limits.workspace_margin_m,
            settings.limits.z_max_m,
            settings.limits.min_dexterity,
            settings.limits.joint_speed_rad_s * period_s,
            *_wrist_limits(settings, period_s),
            settings.tool.build(wrist=settings.wrist.enabled),
        )
        jog = settings.jog
        return cls(
            RobotModel(gate),
            tuple(j.servo_id for j in joints),
            period_s,
            Limits(jog.max_velocity_m_s, jog.max_acceleration_m_s2, jog.max_jerk_m_s3),
            settings.limits.joint_speed_rad_s,
            settings.safety.estop_action,
            jog.hold_timeout_s,
            settings.safety.torque_on_limit_slack_rad,
            wrist_path_limits(settings),
        )


def _wrist_limits(settings: Settings, period_s: float) -> tuple[float | None, float | None, float]:
    """The gate's wrist limits: (min [rad], max [rad], step per tick [rad]); no wrist: None."""
    wrist = settings.wrist
    if not wrist.enabled:
        return None, None, 0.0
    return wrist.min_angle_rad, wrist.max_angle_rad, wrist.max_speed_rad_s * period_s


def wrist_path_limits(settings: Settings) -> Limits | None:
    """The wrist's limits as a move's fourth axis: its speed limit [rad/s], with the jog's
    ratios of acceleration and jerk to speed (the same time scales as the tip's path);
    None without a wrist."""
    wrist, jog = settings.wrist, settings.jog
    if not wrist.enabled:
        return None
    speed = wrist.max_speed_rad_s
    return Limits(
        speed,
        speed * jog.max_acceleration_m_s2 / jog.max_velocity_m_s,
        speed * jog.max_jerk_m_s3 / jog.max_velocity_m_s,
    )


# ---- safety helpers (the tick uses them too) ----
def motion_allowed(state: LoopState) -> bool:
    return state.torque and not state.estopped and not state.faults


def require_motion(state: LoopState) -> None:
    """Raise MotionRefused saying why the robot may not move now; return if it may."""
    if state.estopped:
        raise MotionRefused("e-stop is active: POST /api/reset first")
    if state.faults:
        raise MotionRefused(f"fault: {state.faults[0].reason}; POST /api/reset first")
    if not state.torque:
        raise MotionRefused('torque is off: POST /api/torque {"enabled": true} first')


def record_fault(state: LoopState, fault: Fault) -> None:
    """Record a fault once per cause (counting repeats) and stop: hold where the robot is.

    The list keeps at most MAX_FAULT_CAUSES causes; the oldest go first, counted in
    ``state.faults_dropped``, so a bus that stays down cannot grow the status without bound.
    """
    for i, seen in enumerate(state.faults):
        if seen.cause == fault.cause:
            state.faults[i] = seen.again(fault)
            state.source = None
            return
    log.error("fault: %s", fault.reason)
    if len(state.faults) >= MAX_FAULT_CAUSES:
        del state.faults[0]
        state.faults_dropped += 1
    state.faults.append(fault)
    stop_motion(state)


def stop_motion(state: LoopState) -> None:
    """After torque off, e-stop or a fault: no source, and the next motion starts afresh.

    The servos keep their last goal, so ``goal_m`` becomes that held point (NaN with torque
    off: the loop uses no setpoint then); the robot may have been pushed, have sagged or
    have fallen meanwhile, so the next motion starts from the measured position.
    """
    state.source = None
    state.settle_rad = None
    state.resync = True
    state.phi_goal_rad = None  # a wrist stops where it is commanded
    state.hold_deadline_s = state.hold_velocity_m_s = None
    state.goal_m = state.commanded_point_m.copy() if state.torque else np.full(3, np.nan)


def start_point(state: LoopState) -> np.ndarray:
    """Where a new path starts: the commanded point, else (first motion after torque off,
    e-stop or a fault, or nothing commanded yet) the measured one (``LoopState.start_m``,
    which snapshots carry as ``start_m`` for plans made in other threads)."""
    return state.start_m


def start_joints(state: LoopState) -> np.ndarray:
    """The joints a joint-space path starts from, by the same rule as :func:`start_point`."""
    if state.resync and state.joints is not None:
        return state.joints.position_rad
    return state.reference_rad


def start_phi(state: LoopState) -> float:
    """The wrist angle a path starts from [rad]: the goal last written (the wrist holds it,
    and its next goal steps from it: app/control/wrist.py ``next_phi``), else (none since
    torque on) the one read, else the one the loop holds the tool at."""
    if state.phi_commanded_rad is not None:
        return state.phi_commanded_rad
    if state.wrist is not None and math.isfinite(state.wrist.position_rad):
        return float(state.wrist.position_rad)
    return state.phi_rad


def begin_motion(state: LoopState, source: GoalSource) -> None:
    """Make ``source`` the active one; the first after a stop says where it starts from.

    A wrist turning towards a move's target (the goal ahead of the angle the tip's goals
    are at) stops where the move had taken it: the new motion starts from there."""
    if state.resync:
        state.notice = "starting from the measured position"
        state.resync = False
    else:
        state.notice = None
    if state.phi_goal_rad is not None and isinstance(state.source, MoveSource):
        state.phi_goal_rad = state.phi_rad
    state.source = source


# ---- motion ----
def check_goal(
    gate: Gate, point: Any, phi_rad: float, near_rad: np.ndarray
) -> tuple[np.ndarray, float]:
    """A jog target's tip [m] (3,) and wrist angle [rad], checked strictly in the caller's
    thread: GoalRejected for a wrist angle beyond its limits, a tip whose platform point is
    outside the workspace (with the nearest), or one the IK cannot reach from ``near_rad``."""
    phi = gate.check_phi(phi_rad)
    goal = gate.check_point(point, phi)
    gate.solve(goal, near_rad, phi)
    return goal, phi


def check_vector(value: Any, name: str) -> np.ndarray:
    """``value`` as 3 finite numbers (a jog step [m], a held jog's velocity [m/s]);
    GoalRejected naming ``name`` otherwise."""
    vector = np.asarray(value, dtype=np.float64)
    if vector.shape != (3,) or not np.isfinite(vector).all():
        raise GoalRejected(f"{name}: expected 3 finite numbers, got {value!r}")
    return vector


def ordered_gains(gains: dict[int, Any], servo_ids: tuple[int, ...]) -> list[Any]:
    """Position gains per leg servo id, in joint order; ValueError naming the ids that are
    not the legs' (or the legs' that are missing)."""
    unknown = sorted(set(gains) - set(servo_ids))
    missing = [sid for sid in servo_ids if sid not in gains]
    if unknown or missing:
        raise ValueError(
            f"gains: servo ids {unknown or missing} are not the legs' {list(servo_ids)}"
        )
    return [gains[sid] for sid in servo_ids]


def check_move(
    gate: Gate,
    point: Any,
    joints: Any,
    joint_space: bool,
    near_rad: np.ndarray,
    phi_rad: float = 0.0,
) -> tuple[np.ndarray, bool]:
    """A move's target and whether it is in joint space, checked in the caller's thread.

    Exactly one of ``point`` (the tool tip [m] at wrist angle ``phi_rad``) or ``joints``
    [rad]; a point must be reachable from ``near_rad``, and a joint-space move to a point
    goes to its joints.
    """
    if (point is None) == (joints is None):
        raise GoalRejected("give exactly one of position_m or joints_rad")
    phi_rad = gate.check_phi(phi_rad)
    if joints is not None:
        return gate.check_joints(np.asarray(joints, dtype=np.float64)), True
    goal = gate.check_point(point, phi_rad)
    target = gate.solve(goal, near_rad, phi_rad)  # refuses a point with no usable joints
    return (target, True) if joint_space else (goal, False)


def jog_source(state: LoopState, ctx: CommandContext, renewal: bool = False) -> JogSource:
    """The active jog source, or a new one starting where the next motion starts.

    A new command clears the last one's notice; a ``renewal`` (a held jog's heartbeat)
    keeps it, so a notice about the hold's start stays visible while it is held.
    """
    require_motion(state)
    if isinstance(state.source, JogSource):
        if not renewal:
            state.notice = None
    else:
        begin_motion(state, JogSource(start_point(state), ctx.jog_limits, ctx.period_s))
    assert isinstance(state.source, JogSource)
    return state.source


PHI_SAME_RAD = 1e-9  # a goal's wrist angle this close to the wrist's goal does not turn it


def jog_to(
    state: LoopState,
    ctx: CommandContext,
    goal: np.ndarray,
    speed_m_s: float | None = None,
    phi_rad: float = 0.0,
) -> list[float]:
    """Jog the tip towards ``goal`` [m] at wrist angle ``phi_rad`` [rad] (both already
    gated), starting a jog source if none is active; ``speed_m_s`` caps its speed per axis
    (None: the configured jog limit).

    A goal that turns a fitted wrist goes as a :func:`move` instead (the jog's limits), with
    phi the path's fourth axis: a jog would put the legs at the new angle at once while the
    wrist still turns, the tip off its goal by up to the tool offset times the turn."""
    wrist = ctx.wrist_limits is not None and ctx.gate.wrist_min_rad is not None
    if wrist and abs(phi_rad - start_phi(state)) > PHI_SAME_RAD:
        state.hold_deadline_s = state.hold_velocity_m_s = None  # it ends a held jog
        move(state, ctx, goal, None, False, phi_rad)
        return goal.tolist()
    source = jog_source(state, ctx)
    _hold_tool_at(state, ctx, phi_rad)
    return _retarget(state, source, goal, speed_m_s)


def _hold_tool_at(state: LoopState, ctx: CommandContext, phi_rad: float) -> None:
    """The tip's goals are at wrist angle ``phi_rad`` [rad] (already gated: 0 without a
    wrist); a wrist servo turns there (app/control/wrist.py)."""
    state.phi_rad = phi_rad
    if ctx.gate.wrist_min_rad is not None:
        state.phi_goal_rad = phi_rad


def _retarget(
    state: LoopState, source: JogSource, goal: np.ndarray, speed_m_s: float | None
) -> list[float]:
    state.hold_deadline_s = state.hold_velocity_m_s = None  # a step or a goal ends a held jog
    source.set_speed(None if speed_m_s is None else np.full(3, speed_m_s))
    source.set_target(goal)
    state.goal_m = goal
    return goal.tolist()


def jog_by(
    state: LoopState, ctx: CommandContext, delta: np.ndarray, speed_m_s: float | None = None
) -> list[float]:
    """Jog by ``delta`` [m], clamped onto what passes, from what the loop holds now.

    The base is read here, in the control thread, when the command runs: the active jog's
    aim (so steps add up), else where the next motion starts (the commanded point, or the
    measured one after a stop); never a goal a client remembered.
    """
    source = jog_source(state, ctx)
    base = source.aim_m
    goal = ctx.gate.clamp_towards(base, base + delta, state.reference_rad, state.phi_rad)
    return _retarget(state, source, goal, speed_m_s)


def move(
    state: LoopState,
    ctx: CommandContext,
    target: np.ndarray,
    duration_s: float | None,
    joint_space: bool,
    phi_rad: float = 0.0,
) -> dict:
    """Smooth move to ``target``: joint angles [rad] if ``joint_space``, else a tip [m] at
    wrist angle ``phi_rad`` [rad] (already gated).

    With a wrist, phi is the path's fourth axis (`WristAxis`, within the wrist's speed
    limit): it turns from where it is to ``phi_rad`` along the same trajectory as the
    three others, arriving with them; the tick takes each setpoint's phi as the wrist's
    goal and the tip's angle. Without one, phi stays ``phi_rad`` (0).
    """
    require_motion(state)
    if joint_space:
        speed = ctx.joint_speed_rad_s
        limits = Limits(0.5 * speed, 4.0 * speed, 40.0 * speed)
        start = start_joints(state)
        goal = ctx.gate.tip(ctx.robot.fk(target).points, phi_rad)
    else:
        limits, start, goal = ctx.jog_limits, start_point(state), target
    wrist = None
    if ctx.wrist_limits is not None and ctx.gate.wrist_min_rad is not None:
        wrist = WristAxis(start_phi(state), phi_rad, ctx.wrist_limits)
    source = MoveSource(start, target, limits, duration_s, joint_space, wrist)
    begin_motion(state, source)
    if wrist is None:
        _hold_tool_at(state, ctx, phi_rad)
    state.goal_m = goal
    return {"duration_s": source.duration_s}


def run_source(state: LoopState, source: GoalSource, start_m: np.ndarray, tol_m: float) -> str:
    """Make ``source`` the active one if the robot is still within ``tol_m`` of ``start_m``."""
    require_motion(state)
    moved = float(np.linalg.norm(start_point(state) - start_m))
    if math.isfinite(tol_m) and not moved <= tol_m:
        raise MotionRefused(f"the robot moved {moved * 1e3:.1f} mm since the plan; start again")
    begin_motion(state, source)
    return source.name


def stop_source(state: LoopState, source: GoalSource) -> bool:
    """Stop ``source`` if it is the active one (the robot holds); False if it was not."""
    if state.source is not source:
        return False
    state.source = None
    state.goal_m = state.commanded_point_m.copy()  # the servos hold the last command
    return True


# ---- torque, e-stop, reset ----
def torque_to(state: LoopState, ctx: CommandContext, bus: ServoBus, enabled: bool) -> bool:
    """Torque on (holding where the robot is, so nothing moves) or off (stopping any source).

    Torque on while it is on keeps holding the commanded joints (not the sagged measured
    ones); from off it holds the measured joints, where the relaxed arm is. A relaxed arm
    hangs near its joint limits and can come to rest just past one (the twin rests at 95 deg
    against a 94.5 deg limit, or at 100 deg): up to ``ctx.torque_on_slack_rad`` past, it
    holds where it is and the loop then steps it to the nearest joints inside the limits at
    the joint speed limit (``state.settle_rad``). Farther
    (a relaxed arm still swinging, or pushed past them): MotionRefused, since holding there
    would command the servos beyond their limits.
    """
    if enabled:
        if state.estopped or state.faults:
            require_motion(state)  # raises with the reason
        if state.joints is None:
            raise MotionRefused("no joint state read yet: check the bus")
        hold, point = held(state)
        settle = goal = None
        if not state.torque:  # a relaxed arm resting just past a limit is taken back inside
            settle, goal = _into_limits(ctx, hold, state.phi_rad)
        bus.write_goal(hold)  # where it is, so enabling torque moves nothing
        bus.torque(True)
        state.commanded_rad, state.commanded_point_m = hold, point
        state.goal_m = (point if goal is None else goal).copy()
        state.settle_rad = settle  # the tick steps there at the joint speed limit
    else:
        bus.torque(False)
    state.torque = enabled
    if not enabled:
        stop_motion(state)
    return enabled


def _into_limits(
    ctx: CommandContext, joints_rad: np.ndarray, phi_rad: float
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """For a relaxed arm at ``joints_rad`` (3,) [rad]: (None, None) inside the limits; up
    to ``ctx.torque_on_slack_rad`` past them, the nearest joints inside and their tool tip
    [m] at wrist angle ``phi_rad``; MotionRefused farther past."""
    low, high = np.asarray(ctx.gate.joint_min_rad), np.asarray(ctx.gate.joint_max_rad)
    for i, (value, lo, hi) in enumerate(zip(joints_rad, low, high, strict=True)):
        if not lo - ctx.torque_on_slack_rad <= value <= hi + ctx.torque_on_slack_rad:
            raise MotionRefused(
                f"joint {i + 1} is at {math.degrees(value):.1f} deg, outside its limits "
                f"[{math.degrees(lo):.1f}, {math.degrees(hi):.1f}] deg by more than "
                f"{math.degrees(ctx.torque_on_slack_rad):.1f} deg: torque on would hold it "
                "there; wait for the arm to come to rest inside them (or move it by hand)"
            )
    inside = np.clip(joints_rad, low, high)
    if np.array_equal(inside, joints_rad):
        return None, None
    fk = ctx.robot.fk(inside)
    if not fk.ok:
        raise MotionRefused("torque on: the joints inside the limits have no platform point")
    return inside, ctx.gate.tip(np.asarray(fk.points, dtype=np.float64), phi_rad)


def held(state: LoopState) -> tuple[np.ndarray, np.ndarray]:
    """What a hold keeps, (joints [rad], point [m]): the commanded ones while torque stayed
    on, else (relaxed, or nothing commanded yet) the measured ones. Copies."""
    if state.torque and state.commanded_rad is not None:
        return state.commanded_rad.copy(), state.commanded_point_m.copy()
    assert state.joints is not None  # callers check
    return state.joints.position_rad.copy(), state.point_m.copy()


def estop_now(state: LoopState, ctx: CommandContext, bus: ServoBus) -> str:
    """Stop at once: hold, or release torque, per ``ctx.estop_action``.

    The hold keeps the commanded joints while torque stayed on (no ratchet: the measured
    position sags under load, and holding it would lower the arm each e-stop); with torque
    off (or nothing commanded yet) the measured ones.
    """
    state.estopped = True
    try:
        if ctx.estop_action == "release" or state.joints is None:
            bus.torque(False)
            state.torque = False
        else:
            hold, point = held(state)
            bus.write_goal(hold)
            state.commanded_rad, state.commanded_point_m = hold, point
    except BusError as exc:  # still e-stopped; say the bus did not answer
        state.warning = f"e-stop could not reach the servos: {exc}"
    stop_motion(state)
    return ctx.estop_action


def reset_now(state: LoopState, ctx: CommandContext, bus: ServoBus) -> dict:
    """Clear e-stop and faults, rebooting the servos whose last read had hardware errors."""
    errors = state.joints.hardware_errors if state.joints is not None else ((),) * 3
    failing = [sid for sid, names in zip(ctx.servo_ids, errors, strict=True) if names]
    if failing:
        bus.reboot(failing)
        state.torque = False  # a reboot leaves torque off
    stop_motion(state)  # the servos keep holding what they held (no new goal is written)
    state.faults.clear()
    state.faults_dropped = 0
    state.estopped = False
    state.warning = None
    state.following.reset()
    state.freshness.reset()
    state.misses.ok()
    return {"rebooted": failing}


OPERATOR_SOURCES = ("jog", "move")  # the sources an operator drives live (go-to, jogs)


def link_lost(state: LoopState, why: str, stop_runs: bool = True) -> str | None:
    """The link that commands the robot is lost: the operator's motion stops and the robot
    holds where it is (a jog brakes to a stop within the jog limits, a move stops where it
    is commanded, a held jog is released); a run or a hold-in-world too when
    ``stop_runs``. ``why`` goes to the notice. Returns the name of the motion stopped
    (None: none was running)."""
    source = state.source
    if source is None:
        return None
    if source.name not in OPERATOR_SOURCES and not stop_runs:
        return None
    held = state.hold_velocity_m_s is not None
    if isinstance(source, JogSource) and source.at_rest and not held:
        return None  # a jog standing at its goal holds a point: nothing moves
    state.hold_deadline_s = state.hold_velocity_m_s = None
    if isinstance(source, JogSource):
        source.brake()
    else:
        stop_source(state, source)
    state.notice = why
    return source.name
