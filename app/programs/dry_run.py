"""The dry run: a checked program's timed path played on a headless twin, before it runs.

The same path the run would play goes, tick by tick at the loop period, through what the
live loop does with it (the gate's IK on the followed branch, its per-tick joint step
limit; feed-forward's lead when asked) into a simulated bus of its own
(``hardware.sim.SimBus`` with ``realtime=False``: the MuJoCo twin and the XM430's
firmware model, stepped offline as fast as the CPU goes, never the live robot). At each
tick the error is the goal minus the forward kinematics of the encoder angles the bus
reports, as a run's log records it (thesis Table 6.1: goal - FK), so the prediction is
comparable with the run's own per-line figures (``stats.program.lines``).

The twin is the server's simulated robot (``backend = "sim"``) with this config's
calibrations, built exactly as the controller's model (the gate's robot: a geometry
calibration's per-leg one once applied) believes the robot is; it predicts what the model
knows (servo lag, gravity, the links'
inertia), not a real robot's friction or backlash. A program that turns the wrist (A
words) plays its legs at the planned phi, the wrist taken to follow its plan exactly (the
twin here has the three legs; the tip is measured at the planned phi).

The physics costs about a millisecond of CPU per loop tick, so the dry run is capped:
a program that lasts more than ``[programs] dry_run_max_s`` is refused (DryRunRefused).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from app.config import Settings
from app.control.commands import CommandContext
from app.control.errors import GoalRejected
from app.control.gate import Gate
from app.programs.check import CheckedProgram
from hardware.sim import SimBus, SimBusConfig, TwinConfig
from kinematics import PerLegRotaryDelta, RotaryDelta

SETTLE_S = 0.5  # the arm held at the start first, as a robot holding before a run is


class DryRunRefused(ValueError):
    """A dry run that is not done: its message names the field and the reason."""


@dataclass(frozen=True)
class LineError:
    """The predicted tracking error over one program line: samples (loop ticks), RMSE of
    the error's magnitude sqrt(mean |e|^2) [m] and its largest magnitude [m]."""

    line: int
    samples: int
    rmse_m: float
    max_m: float


@dataclass(frozen=True)
class DryRun:
    """ok: the check passed; duration_s [s] of the path played; lines: the error per
    program line in execution order; rmse_m: per axis (x, y, z) over the whole path [m];
    max_m: the largest |e| [m]."""

    ok: bool
    duration_s: float
    lines: list[LineError]
    rmse_m: list[float]
    max_m: float

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def line_errors(lines: np.ndarray, error: np.ndarray) -> list[LineError]:
    """Per line of ``lines`` (N,) in the order first met: the error ``error`` (N, 3) [m]
    as :class:`LineError` (the rule of app/runs/stats.py line_stats, which a run's record
    uses; the two layers do not import each other)."""
    labels = np.asarray(lines)
    magnitude = np.linalg.norm(np.asarray(error, dtype=np.float64), axis=1)
    order = labels[np.sort(np.unique(labels, return_index=True)[1])]
    out = []
    for line in order:
        values = magnitude[labels == line]
        rmse = float(np.sqrt(np.mean(values**2)))
        out.append(LineError(int(line), int(values.size), rmse, float(values.max())))
    return out


def _bus(settings: Settings, robot: Any) -> SimBus:
    """A headless twin built as ``robot`` (the controller's model) is."""
    if isinstance(robot, PerLegRotaryDelta):
        twin_robot, true_robot = robot.nominal(), robot
    elif isinstance(robot, RotaryDelta):
        twin_robot, true_robot = robot, None
    else:
        raise DryRunRefused("robot.type: the twin models rotary Deltas only")
    joints = tuple(j.calibration() for j in settings.hardware.joints)
    twin = TwinConfig(robot=twin_robot, joints=joints, true_robot=true_robot)
    return SimBus(SimBusConfig(twin=twin, realtime=False, torque_on_at_start=True))


def dry_run(
    checked: CheckedProgram,
    settings: Settings,
    *,
    feedforward: bool = False,
    gate: Gate | None = None,
) -> DryRun:
    """Play ``checked``'s path on a headless twin and predict its tracking error.

    Args:
        checked: a program as :func:`app.programs.check.check_program` planned it (its
            path starts at the report's ``start_m``).
        settings: the robot, calibrations, loop rate and limits (the server's).
        feedforward: command the point ``[runs] feedforward_lead_s`` ahead, as a run with
            feed-forward does (the error is still goal - FK).
        gate: the limits and robot model in force (the controller's; None: the config's).

    Returns:
        DryRun: the error per line (only lines with motion or a dwell: the samples spent
        on them), per axis and at worst.

    Raises:
        DryRunRefused: a program longer than ``[programs] dry_run_max_s``, or a robot the
            twin does not model.
    """
    path, report = checked.path, checked.report
    limit_s = settings.programs.dry_run_max_s
    if path.duration_s > limit_s:
        raise DryRunRefused(
            f"gcode: the program lasts {path.duration_s:.1f} s, over the dry run's limit of "
            f"{limit_s:g} s (programs.dry_run_max_s); check it without the dry run"
        )
    ctx = CommandContext.from_settings(settings)
    gate = gate or ctx.gate
    robot, period_s = gate.robot, ctx.period_s
    bus = _bus(settings, robot)
    if not path.segments:  # nothing moves
        return DryRun(report.ok, 0.0, [], [0.0, 0.0, 0.0], 0.0)
    # the loop's ticks after the start: tick k plays t = k dt (TrajectorySource.next)
    count = max(1, math.ceil(path.duration_s / period_s - 1e-9))
    times = np.minimum(np.arange(1, count + 1) * period_s, path.duration_s)
    goals = path.evaluate(times, (0,))[0]
    lead = settings.runs.feedforward_lead_s if feedforward else 0.0
    ahead = np.minimum(times + lead, path.duration_s)
    commanded = path.evaluate(ahead, (0,))[0] if lead else goals
    lines = path.line_at(times)
    phi_goal, phi_ahead = path.phi_at(times), path.phi_at(ahead)  # the wrist's plan [rad]
    start = path.evaluate(np.zeros(1), (0,))[0][0]
    phi0 = float(path.phi_at(np.zeros(1))[0])
    reference = robot.ik(gate.platform(start, phi0)).joints  # the path is the tool tip's
    try:
        reference = gate.solve(start, reference, phi0)
    except GoalRejected as exc:
        raise DryRunRefused(f"start_m: the program's start cannot be held: {exc}") from exc
    bus.connect()
    try:
        bus.twin.reset(reference)
        bus.write_goal(reference)
        bus.advance(SETTLE_S)
        errors = np.empty((len(times), 3))
        for k in range(len(times)):
            measured = gate.tip(robot.fk(bus.read_state().position_rad).points, phi_goal[k])
            errors[k] = goals[k] - measured
            phi = float(phi_ahead[k])
            try:  # as the loop: a point the gate refuses is not followed (the robot holds)
                joints = gate.solve(gate.clamp_point(commanded[k], phi), reference, phi)
            except GoalRejected:
                joints = None
            if joints is not None:
                reference = gate.limit_step(joints, reference)
                bus.write_goal(reference)
            bus.advance(period_s)
    finally:
        bus.disconnect()
    finite = np.isfinite(errors).all(axis=1)
    errors, lines = errors[finite], lines[finite]
    return DryRun(
        ok=report.ok,
        duration_s=path.duration_s,
        lines=line_errors(lines, errors),
        rmse_m=np.sqrt(np.mean(errors**2, axis=0)).tolist() if len(errors) else [math.nan] * 3,
        max_m=float(np.linalg.norm(errors, axis=1).max()) if len(errors) else math.nan,
    )
