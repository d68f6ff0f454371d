"""``deltadash ik`` and ``deltadash fk``: the configured robot's kinematics from the command line.

Both speak millimetres and degrees by default, and SI (metres, radians) with ``--si``. Each
number may carry its unit (``-240 mm``, ``30.1 deg``, ``0.525 rad``), which wins over the
default, so what one command prints can be pasted into the other. Every number printed
carries its unit; ``--json`` prints SI only (``point_m``, ``joints_rad``), as the API does.

Refusals: ``fk`` refuses a joint angle outside the configured joint limits
(``hardware.joints[i].min_angle_rad`` / ``max_angle_rad``, exit 2); ``ik`` says when a
point is outside the workspace, needs a joint outside its limits or is one the gate refuses
(above the ceiling, within the margin of the boundary, too near a singularity), and gives
the nearest point the gate accepts as a goal (``app.server.sections.nearest``, the same
function as the page's ``GET /api/workspace/nearest`` and a refused goal's ``nearest_m``;
exit 1). ``ik`` speaks platform points, so its gate has no tool. Bad input exits 2.

Only the standard library is imported at module level: the maths and the settings are
imported when a command runs, so that ``deltadash --help`` stays fast.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any

from app.cli.numbers import parse_number

# unit word -> (kind, factor to SI)
_UNITS = {
    "mm": ("length", 1e-3),
    "m": ("length", 1.0),
    "deg": ("angle", math.pi / 180),
    "rad": ("angle", 1.0),
}
_EPILOG = (
    "Numbers are mm (ik) and degrees (fk) unless --si; a unit after a number (mm, m, deg, "
    "rad) wins, so ik's output pastes into fk and back. A decimal comma is read as a "
    "decimal point (10,5 is 10.5, as on the page). Exit 0: answered; 1: no answer "
    "(outside the workspace or the joint limits); 2: refused or bad input."
)


class UnitError(ValueError):
    """Input that cannot be read as three numbers of the expected kind."""


def add_parsers(commands: argparse._SubParsersAction) -> None:
    """Register ``ik`` and ``fk`` on the app's sub-command parsers."""
    ik = commands.add_parser(
        "ik",
        help="joint angles for a platform point (mm in, degrees out)",
        description="Inverse kinematics of the configured robot (default: the thesis's).",
        epilog=_EPILOG,
    )
    ik.add_argument("values", nargs="+", metavar="X Y Z", help="the point [mm], e.g. 0 0 -240")
    _common(ik)
    ik.set_defaults(handler=_ik)
    fk = commands.add_parser(
        "fk",
        help="platform point for joint angles (degrees in, mm out)",
        description="Forward kinematics of the configured robot (default: the thesis's).",
        epilog=_EPILOG,
    )
    fk.add_argument("values", nargs="+", metavar="J1 J2 J3", help="joint angles [deg]")
    fk.add_argument("--deg", action="store_true", help=argparse.SUPPRESS)  # the old flag
    _common(fk)
    fk.set_defaults(handler=_fk)


def _common(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--si", action="store_true", help="metres and radians in and out instead of mm and deg"
    )
    parser.add_argument("--config", help="TOML config: robot geometry and joint limits")
    parser.add_argument("--json", action="store_true", help="machine-readable output (SI)")


def parse_values(tokens: list[str], kind: str, default_unit: str) -> list[float]:
    """Three SI values from command-line tokens: numbers, each optionally followed by a unit.

    ``["0", "0", "-240", "mm"]``, ``["30.1deg,", "30.1", "deg"]``, ``["(1,", "2,", "3)"]``
    and ``["10,5", "0", "-240"]`` are read: commas ending a word and parentheses are ignored
    (pasted tuples), and a comma between digits is a decimal comma (``10,5`` is 10.5, as on
    the page; app/cli/numbers.py); a word with two separators (``1,2,3``, ``1,234.5``) is
    refused, never read as several numbers. ``kind``: "length" or "angle"; ``default_unit``
    applies to a number with no unit after it.

    Raises:
        UnitError: a word that is neither a number nor a unit of ``kind``, or not 3 numbers.
    """
    words = [w.strip("(),") for t in tokens for w in t.split()]
    numbers: list[list[Any]] = []  # [value, unit or None]
    for word in filter(None, words):
        number, unit = _split(word)
        if number is not None:
            numbers.append([number, unit])
        elif unit is not None and numbers and numbers[-1][1] is None:
            numbers[-1][1] = unit
        elif unit is not None:
            raise UnitError(f"{word!r} follows no number")
        else:
            try:
                parse_number(word)
            except ValueError as exc:  # its reason: not a number, or two separators
                raise UnitError(f"{exc}; a unit is mm, m, deg or rad") from None
    if len(numbers) != 3:
        raise UnitError(f"expected 3 numbers, got {len(numbers)}")
    values = []
    for number, unit in numbers:
        unit = unit or default_unit
        unit_kind, factor = _UNITS[unit]
        if unit_kind != kind:
            wanted = "mm or m" if kind == "length" else "deg or rad"
            raise UnitError(f"{number} {unit}: expected {wanted}")
        values.append(number * factor)
    return values


def _split(word: str) -> tuple[float | None, str | None]:
    for unit in sorted(_UNITS, key=len, reverse=True):
        if word == unit:
            return None, unit
        if word.endswith(unit):
            try:
                return parse_number(word[: -len(unit)]), unit
            except ValueError:
                pass
    try:
        return parse_number(word), None
    except ValueError:
        return None, None


def _length(value_m: float, si: bool) -> str:
    if si:
        return f"{round(value_m, 6) + 0.0:.6f} m"  # + 0.0: no "-0.000"
    return f"{round(value_m * 1e3, 3) + 0.0:.3f} mm"


def _angle(value_rad: float, si: bool) -> str:
    return f"{value_rad:.6f} rad" if si else f"{math.degrees(value_rad):.3f} deg"


def _point(point: Any, si: bool) -> str:
    return ", ".join(_length(float(v), si) for v in point)


# app.config's defaults (the thesis robot, JointSettings' limits, the gate's limits: margin
# [m], ceiling [m], lowest 1/cond(J)), for the fast path below; tests/app/cli/
# test_kinematics.py checks they are the same.
DEFAULT_JOINT_LIMITS_RAD = (-0.6, 1.65)
DEFAULT_GATE_LIMITS = (0.002, -0.06, 0.02)


def _setup(args: argparse.Namespace) -> tuple[Any, list[tuple[float, float]], tuple[float, ...]]:
    """The robot, the joint limits [rad] and the gate's (margin [m], ceiling [m], lowest
    1/cond(J)) of the config (defaults: the thesis robot).

    Without --config and without DELTADASH_ environment variables these are app.config's
    defaults, taken without importing pydantic (a third of ik's start-up time)."""
    import os

    if args.config is None and not any(k.startswith("DELTADASH_") for k in os.environ):
        from kinematics import THESIS_DELTA

        return THESIS_DELTA, [DEFAULT_JOINT_LIMITS_RAD] * 3, DEFAULT_GATE_LIMITS
    from app.config import load_settings

    settings = load_settings(args.config)
    limits = [(j.min_angle_rad, j.max_angle_rad) for j in settings.hardware.joints]
    gate = settings.limits
    return (
        settings.robot.build(),
        limits,
        (gate.workspace_margin_m, gate.z_max_m, gate.min_dexterity),
    )


def _gate_refuses(robot: Any, point: list[float], joints: list[float], gate: Any) -> list[str]:
    """Why the gate (app/control/gate.py) would refuse a platform goal whose IK and joint
    limits pass: its ceiling, its margin from the workspace's boundary, its singularity
    margin (``gate``: margin [m], ceiling [m], lowest 1/cond(J)). Empty when it accepts."""
    margin, ceiling, lowest = gate
    problems = []
    if point[2] > ceiling:
        problems.append(f"it is above the ceiling z = {ceiling * 1e3:.3f} mm (limits.z_max_m)")
    if not bool(robot.reachable(point, margin=margin)):
        problems.append(
            f"it is within {margin * 1e3:.3f} mm of the workspace's boundary "
            "(limits.workspace_margin_m)"
        )
    dexterity = float(robot.dexterity(joints))
    if not dexterity >= lowest:
        problems.append(
            f"it is too close to a singularity (1/cond(J) = {dexterity:.3f} < {lowest}, "
            "limits.min_dexterity)"
        )
    return problems


def _outside(joints: list[float], limits: list[tuple[float, float]]) -> list[str]:
    """One sentence per joint outside its limits, naming the value and the limit."""
    problems = []
    for i, (value, (low, high)) in enumerate(zip(joints, limits, strict=True)):
        if not low <= value <= high:
            bound, name = (low, "min") if value < low else (high, "max")
            problems.append(
                f"joint {i + 1} = {math.degrees(value):.3f} deg ({value:.4f} rad) is "
                f"{'below' if value < low else 'above'} its limit {math.degrees(bound):.3f} deg "
                f"(hardware.joints[{i}].{name}_angle_rad = {bound})"
            )
    return problems


def _refuse(message: str, code: int) -> int:
    print(f"error: {message}", file=sys.stderr)
    return code


def _gate(args: argparse.Namespace) -> Any:
    """The gate of the config (app/control/commands.py, as the server builds it), without a
    tool: ``ik`` points are platform centres."""
    from dataclasses import replace

    from app.config import load_settings
    from app.control.commands import CommandContext
    from kinematics import Tool

    gate = CommandContext.from_settings(load_settings(args.config)).gate
    return replace(gate, tool=Tool())


def nearest_accepted(args: argparse.Namespace, point: list[float]) -> list[float]:
    """The point (3,) [m] nearest ``point`` (3,) [m] that the config's gate accepts as a
    goal: ``app.server.sections.nearest``, the one the page and the API offer."""
    import numpy as np

    from app.server import sections

    found = sections.nearest(_gate(args), np.asarray(point, dtype=np.float64))
    return [float(v) for v in found]


def _ik(args: argparse.Namespace) -> int:
    try:
        point = parse_values(args.values, "length", "m" if args.si else "mm")
    except UnitError as exc:
        return _refuse(f"ik X Y Z: {exc}", 2)
    robot, limits, gate = _setup(args)
    result = robot.ik(point)
    joints = [float(v) for v in result.joints]
    ok = bool(result.ok)
    problems = _outside(joints, limits) if ok else []
    refused = _gate_refuses(robot, point, joints, gate) if ok and not problems else []
    payload: dict[str, Any] = {
        "point_m": point,
        "ok": ok and not problems and not refused,
        "joints_rad": [None if math.isnan(v) else v for v in joints],
    }
    if not payload["ok"]:  # the whole gate's nearest point, as the page offers it
        payload["nearest_m"] = nearest_accepted(args, point)
    if problems or refused:
        payload["problems"] = problems + refused
    if args.json:
        print(json.dumps(payload))
        return 0 if payload["ok"] else 1
    if payload["ok"]:
        angles = ", ".join(_angle(v, args.si) for v in joints)
        print(f"IK ({_point(point, args.si)}) -> joints {angles}")
        return 0
    if problems:
        print(f"unreachable: ({_point(point, args.si)}) needs " + "; ".join(problems))
    elif refused:
        angles = ", ".join(_angle(v, args.si) for v in joints)
        print(f"IK ({_point(point, args.si)}) -> joints {angles}")
        print("refused as a goal: " + "; ".join(refused))
    else:
        where = _point(point, args.si)
        print(f"unreachable: ({where}) is outside the workspace (IK has no solution)")
    print(f"nearest point the gate accepts: ({_point(payload['nearest_m'], args.si)})")
    return 1


def _fk(args: argparse.Namespace) -> int:
    default = "deg" if args.deg or not args.si else "rad"
    try:
        joints = parse_values(args.values, "angle", default)
    except UnitError as exc:
        return _refuse(f"fk J1 J2 J3: {exc}", 2)
    robot, limits, _ = _setup(args)
    problems = _outside(joints, limits)
    if problems:
        return _refuse("refused: " + "; ".join(problems), 2)
    result = robot.fk(joints)
    payload = {
        "joints_rad": joints,
        "ok": bool(result.ok),
        "point_m": [None if math.isnan(v) else float(v) for v in result.points],
    }
    if args.json:
        print(json.dumps(payload))
    elif result.ok:
        angles = ", ".join(_angle(v, args.si) for v in joints)
        print(f"FK ({angles}) -> platform ({_point(result.points, args.si)})")
    else:
        print("no platform position: the three spheres do not meet")
    return 0 if result.ok else 1
