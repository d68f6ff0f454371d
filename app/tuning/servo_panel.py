"""The servo panel (issue 21; docs/tuning.md, "The servo panel"): per servo, what the
Dynamixel Wizard gives, through the loop and its checks.

- **Gains**: read from the servos themselves (`Controller.read_gains`, in the control
  thread), written one servo at a time (`TuningManager.write`: the set replaced kept for
  revert, the config file written as an apply's), within the XM430 control table's range
  (`GAIN_LIMITS`).
- **A step of one joint** (`plan_joint_step`): a joint-space step of at most
  `MAX_STEP_RAD` from where the arm rests (its commanded joints, the arm still), the other
  joints held, inside the joint limits; a run of kind ``joint-step`` through the run
  manager, so the gate's batch check (workspace, joint limits, singularity, joint speed)
  passes it before anything moves and the recorder logs it at the loop rate like every
  run. `step_response` reads that log back: the goal and measured angle of the joint, and
  the rise time, overshoot and settling time of the measured response.
- **The wrist's servo** (with a [wrist]: the fourth on the bus, `WRIST` as its joint): its
  gains read and written as a leg's; its step is a step of phi (`plan_wrist_step`,
  `WristStepParams`) from where the wrist rests, the legs held, inside the wrist's limits,
  and `wrist_step_response` reads the wrist's goal and measured phi back from the log.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from app.control.controller import Controller
from app.control.errors import GoalRejected, MotionRefused
from app.procedures.lifecycle import require_motion
from app.runs.paths import JointStepParams
from app.tuning.identify import IdentificationError, record_of
from hardware.dynamixel.control_table import RAD_PER_TICK, Reg

KIND = "joint-step"  # the run kind of a panel's step
GAIN_REGISTERS = {  # the API's names -> the XM430's registers (e-manual: 80..91)
    "p": Reg.POSITION_P_GAIN,
    "i": Reg.POSITION_I_GAIN,
    "d": Reg.POSITION_D_GAIN,
    "ff1": Reg.FEEDFORWARD_1ST_GAIN,
    "ff2": Reg.FEEDFORWARD_2ND_GAIN,
}
GAIN_LIMITS = {name: (reg.value.low, reg.value.high) for name, reg in GAIN_REGISTERS.items()}
MAX_STEP_RAD = math.radians(5.0)  # the largest step the panel runs [rad]
MIN_STEP_RAD = math.radians(0.5)  # smaller is a few encoder ticks (0.088 deg each) [rad]
STEP_AT_S = 0.2  # the rest recorded before the step [s]
RAMP_FRACTION = 0.9  # the goal climbs at this share of the joint speed limit
REST_SPEED_RAD_S = 0.05  # every joint slower than this: the arm rests [rad/s]
STALE_SHARE = 0.5  # no fresh read for this share of safety.stale_feedback_s (the loop's
# fault): the arm's state is not known to step from (a few stale ticks are ordinary on a
# loaded twin, whose time may not advance between two reads)
REST_GOAL_M = 1e-6  # a jog this close to its goal stands at it [m]
SETTLE_FRACTION = 0.05  # settled: within 5 % of the measured change (at least one tick)
RISE = (0.1, 0.9)  # the rise time is from 10 % to 90 % of the measured change
PHASES = ("approach", "timed", "stop")


WRIST = 4  # the panel's joint number of the wrist's servo (the legs are 1..3)


def leg_joint(controller: Controller, servo_id: int) -> int:
    """The joint (1..3) whose servo is ``servo_id``. Raises KeyError for another id."""
    ids = list(controller.servo_ids)
    if servo_id not in ids:
        raise KeyError(servo_id)
    return ids.index(servo_id) + 1


def wrist_servo_id(controller: Controller) -> int | None:
    """The wrist's servo id ([wrist] servo_id), None without a wrist."""
    wrist = controller.settings.wrist
    return wrist.servo_id if wrist.enabled else None


def panel_joint(controller: Controller, servo_id: int) -> int:
    """The panel's joint of ``servo_id``: 1..3 for a leg's servo, `WRIST` (4) for the
    wrist's. Raises KeyError for another id."""
    if servo_id == wrist_servo_id(controller):
        return WRIST
    return leg_joint(controller, servo_id)


def panel_servo_ids(controller: Controller) -> list[int]:
    """Every servo the panel offers, in bus order: the legs', then the wrist's."""
    wrist = wrist_servo_id(controller)
    return [*controller.servo_ids, *([] if wrist is None else [wrist])]


def _step_size(step_rad: float) -> None:
    if not MIN_STEP_RAD <= abs(step_rad) <= MAX_STEP_RAD:
        raise GoalRejected(
            f"step_rad: {math.degrees(step_rad):.2f} deg; a step is "
            f"{math.degrees(MIN_STEP_RAD):g} to {math.degrees(MAX_STEP_RAD):g} deg either way"
        )


@dataclass(frozen=True)
class WristStepParams:
    """A step of the wrist angle phi by ``step_rad`` [rad] from ``start_phi_rad`` at
    ``step_at_s``, the legs held at the joints ``start_rad`` (3,) [rad], then hold: the
    wrist servo's step response (the servo panel's step of servo 4). phi climbs at
    ``ramp_rad_s`` [rad/s] (under the wrist's speed limit, which the tick keeps anyway).

    The loop takes tool tips at phi: ``tip_of(joints, phi)`` maps the held joints (3,)
    [rad] and angles (*) [rad] to the tips (*, 3) [m] (the tool turns about the platform's
    z), so the platform stays where it is while the tool turns."""

    start_rad: tuple[float, float, float]
    start_phi_rad: float
    step_rad: float
    ramp_rad_s: float
    tip_of: Callable[[np.ndarray, np.ndarray], np.ndarray] = field(repr=False, compare=False)
    step_at_s: float = 0.2
    duration_s: float = 1.0
    feedforward: bool = False

    phi_field = "step_rad"  # the field to name when the wrist cannot do it

    @property
    def rise_s(self) -> float:
        """How long phi's goal climbs [s]."""
        return abs(self.step_rad) / self.ramp_rad_s

    @property
    def moves_wrist(self) -> bool:
        return True

    def phi_at(self, t: np.ndarray) -> np.ndarray:
        """phi's goal [rad] at timed-part times ``t`` (*) [s]."""
        t = np.asarray(t, dtype=np.float64)
        climbed = np.clip((t - self.step_at_s) / self.rise_s, 0.0, 1.0) * self.step_rad
        return self.start_phi_rad + climbed

    def phi_peak_speed(self) -> float:
        return self.ramp_rad_s

    def derivatives(self, t: np.ndarray, order: int) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)
        if order == 0:
            return self.tip_of(np.asarray(self.start_rad), self.phi_at(t))
        h = 1e-4  # central differences, as JointStepParams: zero where phi stands
        below, above = self.derivatives(t - h, order - 1), self.derivatives(t + h, order - 1)
        return (above - below) / (2.0 * h)

    def peaks(self) -> tuple[float, float, float]:
        return 0.0, 0.0, 0.0  # the approach and stop join it at rest


def _at_rest(controller: Controller) -> tuple[Any, np.ndarray]:
    """The snapshot of an arm at rest and its commanded joints (3,) [rad], a step's start.
    Raises MotionRefused: it may not move (e-stop, fault, torque off), its state is stale,
    a motion runs or it moves."""
    snap = controller.snapshot()
    require_motion(snap)
    stale_ms = STALE_SHARE * controller.settings.safety.stale_feedback_s * 1e3
    if snap.stale and snap.feedback_age_ms > stale_ms:
        raise MotionRefused(
            f"the servos' state is stale (no fresh read for {snap.feedback_age_ms:.0f} ms): "
            "check the bus, then step again"
        )
    if snap.mode not in ("idle", "jog"):
        raise MotionRefused(f"a {snap.mode} is running: a step starts only from rest")
    goal_gap = np.abs(snap.goal_m - snap.point_commanded_m)
    if snap.mode == "jog" and np.isfinite(goal_gap).all() and goal_gap.max() > REST_GOAL_M:
        raise MotionRefused("the arm is on its way to its goal: step once it rests there")
    speed = np.abs(snap.velocity_rad_s)
    if not np.isfinite(speed).all() or speed.max() > REST_SPEED_RAD_S:
        fastest = int(np.nanargmax(speed)) + 1 if np.isfinite(speed).any() else 1
        raise MotionRefused(
            f"the arm is moving (joint {fastest} at {math.degrees(speed[fastest - 1]):.1f} "
            "deg/s): step once it rests"
        )
    start = np.asarray(snap.joints_commanded_rad, dtype=np.float64)
    if not np.isfinite(start).all():
        raise MotionRefused("no commanded joints yet: torque on and hold the arm first")
    return snap, start


def plan_wrist_step(controller: Controller, step_rad: float, duration_s: float) -> WristStepParams:
    """The step of the wrist's phi by ``step_rad`` [rad] from where it rests, the legs held
    where the arm rests; nothing moves (the run manager plans and checks it: the tips at
    each phi, the wrist's limits and speed).

    Raises:
        KeyError: no wrist (404).
        GoalRejected: the step's size, or its end outside the wrist's limits, naming
            ``step_rad`` (422).
        MotionRefused: as `plan_joint_step` (409).
    """
    if wrist_servo_id(controller) is None:
        raise KeyError("wrist")
    _step_size(step_rad)
    snap, start = _at_rest(controller)
    held = snap.phi_commanded_rad if math.isfinite(snap.phi_commanded_rad) else snap.tool_phi_rad
    phi0 = float(held)
    wrist = controller.settings.wrist
    end = phi0 + step_rad
    if not wrist.min_angle_rad <= end <= wrist.max_angle_rad:
        raise GoalRejected(
            f"step_rad: the step's end: phi {math.degrees(end):.1f} deg is outside the "
            f"wrist's limits [{math.degrees(wrist.min_angle_rad):.1f}, "
            f"{math.degrees(wrist.max_angle_rad):.1f}] deg"
        )
    gate, robot = controller.gate, controller.robot
    platform = robot.fk(start).points

    def tip_of(_joints: np.ndarray, phi: np.ndarray) -> np.ndarray:
        angles = np.asarray(phi, dtype=np.float64)
        return gate.tip(np.broadcast_to(platform, (*angles.shape, 3)), angles)

    return WristStepParams(
        start_rad=tuple(float(v) for v in start),  # type: ignore[arg-type]
        start_phi_rad=phi0,
        step_rad=float(step_rad),
        ramp_rad_s=RAMP_FRACTION * wrist.max_speed_rad_s,
        tip_of=tip_of,
        step_at_s=STEP_AT_S,
        duration_s=float(duration_s),
    )


def wrist_step_record(params: WristStepParams, servo_id: int) -> dict[str, Any]:
    """The wrist step's parameters as run.json keeps them (SI)."""
    return {
        "servo_id": servo_id,
        "joint": WRIST,
        "step_rad": params.step_rad,
        "start_rad": list(params.start_rad),
        "start_phi_rad": params.start_phi_rad,
        "step_at_s": params.step_at_s,
        "duration_s": params.duration_s,
        "ramp_rad_s": params.ramp_rad_s,
    }


def plan_joint_step(
    controller: Controller, servo_id: int, step_rad: float, duration_s: float
) -> JointStepParams:
    """The step of ``servo_id``'s joint by ``step_rad`` [rad] from where the arm rests now;
    nothing moves (the run manager plans and checks it).

    Raises:
        KeyError: not a leg's servo (404).
        GoalRejected: the step's size or its end outside the joint limits, naming
            ``step_rad`` (422).
        MotionRefused: the robot may not move (e-stop, fault, torque off), its state is
            stale, or it is not at rest (409).
    """
    joint = leg_joint(controller, servo_id)
    _step_size(step_rad)
    snap, start = _at_rest(controller)
    end = start.copy()
    end[joint - 1] += step_rad
    gate, robot, phi = controller.gate, controller.robot, float(snap.phi_rad)
    try:
        gate.check_joints(end)
    except GoalRejected as exc:
        raise GoalRejected(f"step_rad: the step's end: {exc.reason}") from None

    def tip_of(joints: np.ndarray) -> np.ndarray:
        return gate.tip(robot.fk(joints).points, phi)

    return JointStepParams(
        joint=joint,
        start_rad=tuple(float(v) for v in start),  # type: ignore[arg-type]
        step_rad=float(step_rad),
        ramp_rad_s=RAMP_FRACTION * controller.settings.limits.joint_speed_rad_s,
        tip_of=tip_of,
        step_at_s=STEP_AT_S,
        duration_s=float(duration_s),
        phi_rad=phi,
    )


def step_record(params: JointStepParams, servo_id: int) -> dict[str, Any]:
    """The step's parameters as run.json keeps them (SI)."""
    return {
        "servo_id": servo_id,
        "joint": params.joint,
        "step_rad": params.step_rad,
        "start_rad": list(params.start_rad),
        "step_at_s": params.step_at_s,
        "duration_s": params.duration_s,
        "ramp_rad_s": params.ramp_rad_s,
        "phi_rad": params.phi_rad,
    }


def _crossing(t: np.ndarray, s: np.ndarray, level: float, begin: int) -> float | None:
    """The first time from index ``begin`` at which ``s`` reaches ``level`` (linear
    between samples), or None."""
    above = np.flatnonzero(s[begin:] >= level)
    if above.size == 0:
        return None
    k = begin + int(above[0])
    if k == 0 or s[k - 1] >= level:
        return float(t[k])
    fraction = (level - s[k - 1]) / (s[k] - s[k - 1])
    return float(t[k - 1] + fraction * (t[k] - t[k - 1]))


def _finite(value: float | None) -> float | None:
    return float(value) if value is not None and math.isfinite(value) else None


def step_figures(
    t_s: np.ndarray, goal_rad: np.ndarray, measured_rad: np.ndarray, tail: int = 10
) -> dict[str, float | None]:
    """Rise time, delay, overshoot and settling of a step's measured response, from its
    samples (times (N,) [s], the joint's goal and measured angle (N,) [rad]); t = 0 is the
    first sample whose goal has left the start.

    The figures are of the measured response against its own start and end (the mean of
    the samples before the step and of the last ``tail`` samples), as a step response is
    read: ``rise_time_s`` from 10 % to 90 % of the measured change, ``delay_s`` to 10 %,
    ``overshoot_pct`` beyond the end value [% of the change], ``settling_s`` until it stays
    within ``settle_band_rad`` (5 % of the change, at least one encoder tick) of the end
    value (None: it had not settled by the end of the record). The goal's own error is
    apart: ``steady_error_rad`` is the final goal minus the end value (a P-only loop's sag
    under gravity), ``moved_fraction`` the measured change over the goal's."""
    figures: dict[str, float | None] = dict.fromkeys(
        (
            "rise_time_s",
            "delay_s",
            "overshoot_pct",
            "settling_s",
            "settle_band_rad",
            "steady_error_rad",
            "moved_rad",
            "moved_fraction",
        )
    )
    before = np.flatnonzero(t_s < 0.0)
    after = np.flatnonzero(t_s >= 0.0)
    if before.size == 0 or after.size <= tail:
        return figures
    begin = int(after[0])
    y0 = float(np.mean(measured_rad[before[-min(before.size, tail) :]]))
    end = float(np.mean(measured_rad[-tail:]))
    goal_change = float(goal_rad[-1] - goal_rad[before[-1]])
    moved = end - y0
    figures["moved_rad"] = moved
    figures["steady_error_rad"] = float(goal_rad[-1]) - end
    if goal_change == 0.0:
        return figures
    figures["moved_fraction"] = moved / goal_change
    if abs(moved) < RAD_PER_TICK or moved * goal_change <= 0:  # it did not follow the goal
        return figures
    s = (measured_rad - y0) / moved  # 0 at the start, 1 at the end
    t10, t90 = (_crossing(t_s, s, level, begin) for level in RISE)
    figures["delay_s"] = t10
    if t10 is not None and t90 is not None:
        figures["rise_time_s"] = t90 - t10
    figures["overshoot_pct"] = max(0.0, float(np.max(s[begin:])) - 1.0) * 100.0
    band = max(SETTLE_FRACTION, RAD_PER_TICK / abs(moved))
    figures["settle_band_rad"] = band * abs(moved)
    outside = np.flatnonzero(np.abs(s[begin:] - 1.0) > band)
    if outside.size == 0:
        figures["settling_s"] = 0.0
    elif begin + int(outside[-1]) < len(s) - 1:
        figures["settling_s"] = float(t_s[begin + int(outside[-1]) + 1])
    return {k: _finite(v) for k, v in figures.items()}


def wrist_step_response(rows: Sequence[dict[str, Any]], params: WristStepParams) -> dict[str, Any]:
    """The wrist step's record from its run's log rows, as `step_response` gives a leg's:
    phi's goal (as written to the servo) and measured [rad] per sample, times [s] from the
    step, and its figures."""
    cmd, meas = "phi_commanded_rad", "phi_measured_rad"
    kept = [
        r
        for r in rows
        if r.get("phase") in PHASES and None not in (r.get("t_s"), r.get(cmd), r.get(meas))
    ]
    if not kept:
        empty = np.zeros(0)
        return {
            "clock": "t_s",
            "t_s": [],
            "goal_rad": [],
            "measured_rad": [],
            "figures": step_figures(empty, empty, empty),
        }
    clock = "sim_time_s" if all(r.get("sim_time_s") is not None for r in kept) else "t_s"
    t = np.array([r[clock] for r in kept], dtype=float)
    u = np.array([r[cmd] for r in kept], dtype=float)
    y = np.array([r[meas] for r in kept], dtype=float)
    last = np.append(np.diff(t) > 0, True)  # the last row of each time (identify.record_of)
    t, u, y = t[last], u[last], y[last]
    moved = np.flatnonzero(np.abs(u - params.start_phi_rad) > 1e-9)
    t = t - (float(t[moved[0]]) if moved.size else float(t[0]))
    return {
        "clock": clock,
        "t_s": t.tolist(),
        "goal_rad": u.tolist(),
        "measured_rad": y.tolist(),
        "figures": step_figures(t, u, y),
    }


def step_response(rows: Sequence[dict[str, Any]], params: JointStepParams) -> dict[str, Any]:
    """The step's record from its run's log rows (app/runs/logs.py): the joint's goal and
    measured angle [rad] per sample, times [s] from the step (on the twin its simulated
    time, which a starved simulator keeps, else the loop's: ``clock``), and its figures
    (`step_figures`). An empty record (a run stopped before its first tick) has none."""
    empty: dict[str, Any] = {"clock": "t_s", "t_s": [], "goal_rad": [], "measured_rad": []}
    try:
        record = record_of(rows, params.joint, PHASES)
    except IdentificationError:
        return {**empty, "figures": step_figures(np.zeros(0), np.zeros(0), np.zeros(0))}
    kept = [r for r in rows if r.get("phase") in PHASES]
    clock = "sim_time_s" if all(r.get("sim_time_s") is not None for r in kept) else "t_s"
    t, u, y = record.t_s, record.u_rad, record.y_rad
    moved = np.flatnonzero(np.abs(u - params.start_rad[params.joint - 1]) > 1e-9)
    t0 = float(t[moved[0]]) if moved.size else float(t[0])
    t = t - t0
    return {
        "clock": clock,
        "t_s": t.tolist(),
        "goal_rad": u.tolist(),
        "measured_rad": y.tolist(),
        "figures": step_figures(t, u, y),
    }
