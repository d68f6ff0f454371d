"""``deltadash gcode check FILE``: a G-code program checked on the virtual robot, offline.

The program is planned and every loop sample checked as the server's
``POST /api/programs/check`` does (app/programs/check.py), with the config's robot and
limits (the default config's without ``--config``), from ``programs.start_m`` or
``--start``. No server, no robot: nothing moves. The report is text in mm (per-line
violations) or, with ``--json``, the API's answer (SI). Exit 0: the program passes;
1: it has violations; 2: it cannot be read (its line and word) or bad input.

Only the standard library is imported at module level (``deltadash --help`` stays fast).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

_EPILOG = (
    "Exit 0: the program passes every check; 1: it has violations; 2: it cannot be read "
    "(the line and word are named) or bad input. The subset and the frames: docs/gcode.md."
)


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register ``gcode`` and its ``check`` on the app's sub-command parsers."""
    gcode = commands.add_parser(
        "gcode",
        help="check a G-code program on the virtual robot before it moves",
        description="G-code programs (the subset in docs/gcode.md).",
    )
    sub = gcode.add_subparsers(dest="gcode_command", required=True, metavar="SUBCOMMAND")
    check = sub.add_parser(
        "check",
        help="plan a program and check every loop sample (offline)",
        description="Plan FILE and check every sample of its timed path at the loop rate: "
        "workspace with margin and ceiling, IK on the followed branch, joint limits, joint "
        "speed and acceleration, singularity margin, servo torque.",
        epilog=_EPILOG,
    )
    check.add_argument("file", metavar="FILE", help="the program (text)")
    check.add_argument("--json", action="store_true", help="the report as JSON (SI units)")
    check.add_argument("--config", help="TOML config: robot, limits, [programs]")
    check.add_argument(
        "--start",
        nargs=3,
        type=float,
        metavar=("X", "Y", "Z"),
        help="where the tool starts [mm, base frame] (default programs.start_m)",
    )
    check.add_argument(
        "--work-offset",
        nargs=3,
        type=float,
        metavar=("X", "Y", "Z"),
        help="G54: the program origin in the base frame [mm] (default programs.work_offset_m)",
    )
    check.set_defaults(handler=_check)


def _mm(point: Any) -> str:
    return "(" + ", ".join(f"{v * 1e3:.3f}" for v in point) + ") mm"


def format_report(name: str, report: dict[str, Any], settings: Any) -> str:
    """The report as text, lengths in mm (one line per violation)."""
    violations = report["violations"]
    lines = {v["line"] for v in violations}
    verdict = (
        "PASSES" if report["ok"] else f"FAILS: {len(violations)} violations on {len(lines)} line(s)"
    )
    ratio = report["worst_torque_ratio"]
    out = [
        f"{name}: {verdict}",
        f"  {report['lines']} lines, {report['segments']} segments, "
        f"{report['duration_s']:.3f} s, path {report['length_m'] * 1e3:.1f} mm, "
        f"{report['samples']} samples every {report['period_s'] * 1e3:.1f} ms",
        f"  peak joint speed {report['peak_joint_speed_rad_s'] or 0:.2f} rad/s "
        f"(limit {settings.limits.joint_speed_rad_s:.2f}), "
        f"peak joint acceleration {report['peak_joint_acceleration_rad_s2'] or 0:.0f} rad/s^2 "
        f"(limit {settings.programs.joint_acceleration_rad_s2:.0f})",
        f"  worst 1/cond(J) {report['worst_dexterity'] or 0:.3f} "
        f"(min {settings.limits.min_dexterity}), worst torque ratio "
        + ("n/a" if ratio is None else f"{ratio:.2f}")
        + f" (limit {settings.programs.max_torque_ratio:.2f})",
    ]
    out += [f"  note: {note}" for note in report["notes"]]
    for v in violations:
        out.append(
            f"  line {v['line']}: {v['kind']} at t = {v['t_s']:.3f} s, {_mm(v['point_m'])}: "
            f"{v['message']}"
        )
    return "\n".join(out)


def _check(args: argparse.Namespace) -> int:
    from app.config import ConfigError, load_settings
    from app.programs.check import check_program
    from app.programs.errors import ProgramError

    try:
        settings = load_settings(args.config)
        text = Path(args.file).read_text()
    except (ConfigError, OSError, UnicodeDecodeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    start = None if args.start is None else [v * 1e-3 for v in args.start]
    offset = None if args.work_offset is None else [v * 1e-3 for v in args.work_offset]
    try:
        report = check_program(text, settings, start_m=start, work_offset_m=offset).report
    except ProgramError as exc:
        if args.json:
            print(json.dumps({"detail": str(exc), "line": exc.line or None, "word": exc.word}))
        print(f"error: {args.file}: {exc}", file=sys.stderr)
        return 2
    body = report.to_dict()
    print(json.dumps(body) if args.json else format_report(args.file, body, settings))
    return 0 if report.ok else 1
