"""A program's text to its report: parse, plan, sample at the loop period, verify.

What the API (POST /api/programs/check) and the CLI (``deltadash gcode check``) give.
Needs no server: the robot, the gate's limits and the loop period come from the settings
(the default config's robot when none is given).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from app.config import Settings
from app.control.commands import CommandContext, wrist_path_limits
from app.control.gate import Gate
from app.programs.errors import ProgramError
from app.programs.modal import interpret
from app.programs.planner import PlanLimits, ProgramPath, plan_program
from app.programs.tokens import iter_lines, program_lines
from app.programs.verify import Verification, VerifyLimits, Violation, fold, verify_path
from kinematics.dynamics import THESIS_MASS, MassModel
from kinematics.sizing import XM430_W210_12V


@dataclass(frozen=True)
class ProgramReport:
    """The check's answer. ok: no violation; duration_s [s] and length_m [m] of the
    planned path; violations by move (app/programs/verify.py fold: each program line's
    first cause, then the line's others with folded_under its index); path_m: the path
    decimated for drawing (M, 3) [m]; path_lines: the program line of each path_m point
    (M,) (None where nothing moves); peaks over the samples: joint speed [rad/s] and
    acceleration [rad/s^2], lowest 1/cond(J), highest torque ratio (None: no torque model
    for this robot); lines, segments, samples, period_s [s], chord_tolerance_m [m];
    start_m and work_offset_m (G54) [m] as used; notes: what the operator should know
    (M0 pauses, G64)."""

    ok: bool
    duration_s: float
    length_m: float
    violations: list[Violation]
    path_m: list[list[float]]
    path_lines: list[int | None]
    peak_joint_speed_rad_s: float | None
    peak_joint_acceleration_rad_s2: float | None
    worst_dexterity: float | None
    worst_torque_ratio: float | None
    lines: int
    segments: int
    samples: int
    period_s: float
    chord_tolerance_m: float
    start_m: list[float]
    work_offset_m: list[float]
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (NaN becomes None)."""
        out = asdict(self)
        for violation in out["violations"]:
            violation["point_m"] = list(violation["point_m"])
        return out


@dataclass(frozen=True)
class CheckedProgram:
    """The report and the timed path it was made from (what a run would play)."""

    report: ProgramReport
    path: ProgramPath


def _finite(value: float | None) -> float | None:
    return None if value is None or not math.isfinite(value) else value


def plan_limits(settings: Settings) -> PlanLimits:
    jog, programs = settings.jog, settings.programs
    wrist = wrist_path_limits(settings)  # as a move's: its speed, the jog's time scales
    turn = () if wrist is None else (wrist.velocity, wrist.acceleration, wrist.jerk)
    return PlanLimits(
        jog.max_velocity_m_s,
        jog.max_acceleration_m_s2,
        jog.max_jerk_m_s3,
        programs.max_acceleration_m_s2,
        programs.max_jerk_m_s3,
        programs.chord_tolerance_m,
        1.0 / settings.loop.rate_hz,
        *turn,
    )


def verify_limits(settings: Settings) -> VerifyLimits:
    programs = settings.programs
    robot_type = settings.robot.type
    return VerifyLimits(
        programs.joint_acceleration_rad_s2,
        XM430_W210_12V if robot_type == "rotary" else None,
        _mass(settings) if robot_type == "rotary" else None,
        programs.max_torque_ratio,
    )


def _mass(settings: Settings) -> MassModel:
    """The thesis robot's masses with the configured payload, and a wrist if one is fitted."""
    mass = THESIS_MASS.with_payload(settings.programs.payload_kg)
    return mass.with_wrist() if settings.wrist.enabled else mass


def _decimated(length: int, count: int) -> np.ndarray:
    """About ``count`` evenly spread indices into ``length`` samples, first and last kept."""
    if length <= count:
        return np.arange(length)
    return np.unique(np.linspace(0, length - 1, count).round()).astype(int)


def run_samples(duration_s: float, period_s: float) -> int:
    """Loop periods a run of a program lasting ``duration_s`` [s] logs, as the run
    manager counts them (``PlannedRun.samples``: no approach or stop when the program
    starts where the robot is and ends at rest) against ``runs.max_samples``."""
    return math.ceil((duration_s + period_s) / period_s)


def _too_long(path: ProgramPath, period_s: float, cap: int, name: str) -> str:
    return (
        f"the program lasts {path.duration_s:.0f} s, over {name} = "
        f"{cap} loop periods ({cap * period_s:.0f} s)"
    )


def _line_at(path: ProgramPath, t_s: float) -> int:
    """The program line in execution at ``t_s`` [s] (0 for a program with no segment)."""
    if not path.segments:
        return 0
    return int(path.line_at(np.array([min(t_s, path.duration_s)]))[0])


RUN_DURATION = "run_duration"  # the violation kind of a program longer than a run may be


def run_violation(path: ProgramPath, period_s: float, cap: int) -> Violation:
    """A program too long for a run (``cap`` = ``runs.max_samples`` loop periods): the line
    in execution, the time and the point where a run's log would be full. Its message is
    the reason POST /api/programs/run gives (422 ``line N: <message>``)."""
    t_s = min(cap * period_s, path.duration_s)
    point = path.evaluate(np.array([t_s]), (0,))[0][0]
    message = _too_long(path, period_s, cap, "runs.max_samples") + ": too long to run"
    return Violation(_line_at(path, t_s), RUN_DURATION, message, t_s, tuple(point.tolist()))


def check_program(
    text: str,
    settings: Settings,
    *,
    gate: Gate | None = None,
    start_m: Any = None,
    work_offset_m: Any = None,
    near: Any = None,
    for_run: bool = False,
    start_phi_rad: float = 0.0,
) -> CheckedProgram:
    """Parse, plan and verify ``text`` with ``settings``' robot and limits.

    Args:
        gate: the limits in force (default: built from ``settings``, as the loop does).
        start_m: where the tool is (3,) [m] (default ``programs.start_m``).
        work_offset_m: the G54 origin (3,) [m] (default ``programs.work_offset_m``).
        near: the joints the loop is at (3,) [rad] (default: the knee-out branch at the
            start).
        for_run: the program is about to run (POST /api/programs/run): one longer than a
            run may be (``runs.max_samples``) is refused after planning, before the costly
            checks. Without it such a program is checked all the same (up to
            ``programs.max_samples``) and the report has a ``run_duration`` violation with
            the same words, so a check never passes what a run refuses.
        start_phi_rad: the wrist's angle at the start [rad] (with a wrist: A words turn
            it from there, within the gate's wrist limits; without one A is refused).

    Raises:
        ProgramError: a program that cannot be read or planned (its line and word), or
            one over ``programs.max_lines`` or ``programs.max_samples`` (or, ``for_run``,
            over ``runs.max_samples``: line N is the line in execution when a run's log
            would be full).
    """
    programs = settings.programs
    gate = gate or CommandContext.from_settings(settings).gate
    start = np.asarray(programs.start_m if start_m is None else start_m, dtype=np.float64)
    offset = np.asarray(
        programs.work_offset_m if work_offset_m is None else work_offset_m, dtype=np.float64
    )
    for name, value in (("start_m", start), ("work_offset_m", offset)):
        if value.shape != (3,) or not np.isfinite(value).all():
            raise ProgramError(0, "", f"{name}: expected 3 finite numbers [m]")
    line_count = len(program_lines(text))  # as the tokenizer counts them (CR too)
    if line_count > programs.max_lines:
        raise ProgramError(
            programs.max_lines + 1,
            "",
            f"the program has {line_count} lines, over programs.max_lines = {programs.max_lines}",
        )
    wrist = None
    if gate.wrist_min_rad is not None and gate.wrist_max_rad is not None:
        wrist = (gate.wrist_min_rad, gate.wrist_max_rad)
    start_phi = float(start_phi_rad)
    if not math.isfinite(start_phi):
        raise ProgramError(0, "", "start_phi_rad: expected a finite number [rad]")
    program = interpret(iter_lines(text), start, offset, start_phi, wrist)
    limits = plan_limits(settings)
    path = plan_program(program.segments, limits)
    period_s = limits.period_s
    cap = programs.max_samples  # bounds the check's time and memory
    if path.duration_s / period_s > cap:
        reason = _too_long(path, period_s, cap, "programs.max_samples")
        raise ProgramError(_line_at(path, cap * period_s), "", reason)
    beyond_run = None  # a run's log holds runs.max_samples: POST /api/programs/run refuses more
    if run_samples(path.duration_s, period_s) > settings.runs.max_samples:
        beyond_run = run_violation(path, period_s, settings.runs.max_samples)
        if for_run:  # refused before the costly checks, in the words of the check's violation
            raise ProgramError(beyond_run.line, "", beyond_run.message)
    if path.segments:
        times = path.sample_times(period_s)
        points, velocity, acceleration = path.evaluate(times, (0, 1, 2))
        wrist_motion = tuple(path.wrist(times, (0, 1, 2)))
        lines = path.line_at(times)
    else:  # nothing moves: the tool stays where it is
        times, lines = np.zeros(1), np.zeros(1, dtype=int)
        points, velocity, acceleration = start[None, :], np.zeros((1, 3)), np.zeros((1, 3))
        wrist_motion = (np.full(1, start_phi), np.zeros(1), np.zeros(1))
    near_joints = np.full(3, np.nan) if near is None else np.asarray(near, dtype=np.float64)
    result: Verification = verify_path(
        gate,
        verify_limits(settings),
        times,
        lines,
        points,
        velocity,
        acceleration,
        near_joints,
        period_s,
        wrist_motion if wrist is not None else None,
    )
    violations = list(result.violations)
    if beyond_run is not None:
        violations = sorted([*violations, beyond_run], key=lambda v: v.t_s)
    violations = fold(violations)  # by move: its first cause, the others folded under it
    drawn = _decimated(len(points), programs.path_points)
    report = ProgramReport(
        ok=not violations,
        duration_s=path.duration_s,
        length_m=path.length_m,
        violations=violations,
        path_m=points[drawn].tolist(),
        path_lines=[int(line) if line > 0 else None for line in lines[drawn]],
        peak_joint_speed_rad_s=_finite(result.peak_joint_speed_rad_s),
        peak_joint_acceleration_rad_s2=_finite(result.peak_joint_acceleration_rad_s2),
        worst_dexterity=_finite(result.worst_dexterity),
        worst_torque_ratio=_finite(result.worst_torque_ratio),
        lines=program.lines,
        segments=len(program.segments),
        samples=len(times),
        period_s=period_s,
        chord_tolerance_m=programs.chord_tolerance_m,
        start_m=start.tolist(),
        work_offset_m=offset.tolist(),
        notes=program.notes,
    )
    return CheckedProgram(report, path)
