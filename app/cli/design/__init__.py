"""``deltadash design``: dynamics, motor sizing, workspace analysis and geometric synthesis.

Defaults reproduce the thesis's design problem (ch. 4): its robot (L 0.1558, l 0.2430,
R 0.0844, r 0.038 m), payload 0.2 kg, 4 m/s^2, 0.5 m/s, the 22 cm box (20 cm plus 1 cm
each side) with the landing point (0, 0, -0.075) m, and the bounds of Table 4.2. SI
units on the command line; tables print mm, N m and rpm; --json prints JSON only.
"""

from __future__ import annotations

import argparse
import math

from app.cli.design import synth, workspace
from app.cli.design.arguments import common, emit, mass_args, mass_from, robot_from
from app.cli.numbers import number

# The maths (numpy, scipy, the report) is imported by each handler, not here: building the
# parser must stay cheap so that ``deltadash --help``, ``ik`` and ``fk`` start fast.
SERVOS = ("xm430-12v", "xm430-11v1", "thesis")
_THESIS_CUBE = ([-0.1, -0.1, -0.2903], [0.1, 0.1, -0.0903])  # 20 cm cube centred at -H


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``design`` and its sub-commands on the app's sub-command parsers."""
    parser = subparsers.add_parser(
        "design",
        help="dynamics, motor sizing, workspace and synthesis of a rotary Delta",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    commands = parser.add_subparsers(dest="design_command", required=True)
    _dynamics_parser(commands)
    _size_parser(commands)
    workspace.add_parser(commands)
    synth.add_parser(commands)
    return parser


# ---- dynamics ----
def _dynamics_parser(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser(
        "dynamics",
        help="joint torques for a platform motion [N m]",
        description="Inverse dynamics (thesis eq. 3.89-3.125): the three "
        "torques, positive towards positive theta (link down).",
    )
    p.add_argument("--point", type=number, nargs=3, default=[0.0, 0.0, -0.25], help="P [m]")
    p.add_argument("--velocity", type=number, nargs=3, default=[0.0, 0.0, 0.0], help="[m/s]")
    p.add_argument("--acceleration", type=number, nargs=3, default=[0.0, 0.0, 0.0], help="[m/s^2]")
    p.add_argument(
        "--gravity",
        type=number,
        nargs=3,
        default=[0.0, 0.0, -9.81],
        help="gravity in the base frame [m/s^2] (a tilted drone rotates it)",
    )
    common(p)
    mass_args(p)
    p.set_defaults(handler=_dynamics)


def _dynamics(args: argparse.Namespace) -> int:
    import numpy as np

    from kinematics.dynamics import inverse_dynamics

    mass = mass_from(args).with_payload(args.payload)
    torque = inverse_dynamics(
        robot_from(args), mass, args.point, args.velocity, args.acceleration, args.gravity
    )
    ok = bool(np.isfinite(torque).all())
    payload = {
        "torques_nm": [float(t) if math.isfinite(t) else None for t in torque],
        "ok": ok,
        "point_m": args.point,
    }
    text = (
        ("torques [N m]: " + "  ".join(f"{t:+.4f}" for t in torque))
        if ok
        else ("unreachable or singular point")
    )
    emit(args, payload, text)
    return 0 if ok else 1


# ---- size ----
def _size_parser(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser(
        "size",
        help="motor sizing over a region vs a servo line",
        description="Largest static torque (gravity within --tilt of -z), "
        "peak torque (plus --acceleration in any direction at --speed), "
        "largest joint speed, against the servo's torque-speed line; the "
        "thesis's 0.656 N m, 0.905 N m, 48 rpm beside ours. Exit status 1 if the servo fails.",
    )
    p.add_argument(
        "--region",
        type=number,
        nargs=6,
        metavar=("X0", "Y0", "Z0", "X1", "Y1", "Z1"),
        default=[*_THESIS_CUBE[0], *_THESIS_CUBE[1]],
        help="box corners [m] (default: 20 cm cube centred at z = -0.1903)",
    )
    p.add_argument("--grid", type=int, default=9, help="grid points per axis (9)")
    p.add_argument(
        "--margin",
        type=number,
        default=0.0,
        help="skip points nearer than this to the boundary [m] (0)",
    )
    p.add_argument("--acceleration", type=number, default=4.0, help="[m/s^2] (4)")
    p.add_argument("--speed", type=number, default=0.5, help="[m/s] (0.5)")
    p.add_argument("--tilt", type=number, default=90.0, help="drone tilt limit [deg] (90)")
    p.add_argument(
        "--servo",
        choices=sorted(SERVOS),
        default="xm430-12v",
        help="XM430-W210 datasheet line at 12 V (3.0 N m, 77 rpm), 11.1 V "
        "(2.7 N m, 70 rpm) or the thesis's (2 N m, 72 rpm)",
    )
    p.add_argument("--stall", type=number, help="custom servo stall torque [N m]")
    p.add_argument("--no-load", type=number, help="custom servo no-load speed [rpm]")
    common(p)
    mass_args(p)
    p.set_defaults(handler=_size)


def _size(args: argparse.Namespace) -> int:
    from app.design import report
    from kinematics.dynamics import MassModel
    from kinematics.sizing import (
        XM430_W210_11V1,
        XM430_W210_12V,
        XM430_W210_THESIS,
        Servo,
        region_grid,
        size_motors,
    )

    lines = {"xm430-12v": XM430_W210_12V, "xm430-11v1": XM430_W210_11V1}
    servo = {**lines, "thesis": XM430_W210_THESIS}[args.servo]
    if args.stall or args.no_load:
        servo = Servo("custom", args.stall or servo.stall_nm, args.no_load or servo.no_load_rpm)
    robot, mass = robot_from(args), mass_from(args)
    grid = region_grid(args.region[:3], args.region[3:], args.grid)
    options = {
        "payload_kg": args.payload,
        "acceleration_m_s2": args.acceleration,
        "speed_m_s": args.speed,
        "servo": servo,
        "margin_m": args.margin,
    }
    sized = size_motors(robot, mass, grid, tilt_deg=args.tilt, **options)
    level = size_motors(robot, mass, grid, tilt_deg=0.0, **options)
    link_only = MassModel(
        mass.platform_kg, mass.upper_kg, mass.upper_kg * args.L**2 / 3, mass.lower_kg
    )
    bare = size_motors(robot, link_only, grid, tilt_deg=args.tilt, **options)
    payload = report.sizing_payload(sized, level, bare)
    payload["peak_cause"] = _peak_cause(args, robot, mass, sized, options)
    emit(args, payload, report.sizing_table(payload) + "\n" + report.peak_cause_text(payload))
    return 0 if sized.passes else 1


def _peak_cause(args: argparse.Namespace, robot, mass, sized, options) -> dict:
    """What drives the peak: the pose at its point, the peak at zero speed
    (no velocity terms), and the peak over the region without its top 30 %."""
    from kinematics.sizing import region_grid, size_motors

    point = sized.peak_nm.point
    theta = robot.ik(point).joints
    lower, upper = list(args.region[:3]), list(args.region[3:])
    z_cut = upper[2] - 0.3 * (upper[2] - lower[2])
    grid = region_grid(lower, [*upper[:2], z_cut], args.grid)
    below = size_motors(robot, mass, grid, tilt_deg=args.tilt, **options)
    still = size_motors(
        robot,
        mass,
        region_grid(lower, upper, args.grid),
        tilt_deg=args.tilt,
        **{**options, "speed_m_s": 1e-9},  # 0 would divide by zero in the margins
    )
    return {
        "point_mm": [round(float(v) * 1e3, 2) for v in point],
        "joint": sized.peak_nm.joint + 1,
        "joints_deg": [round(math.degrees(float(t)), 1) for t in theta],
        "boundary_distance_mm": round(-float(robot.signed_distance(point)) * 1e3, 1),
        "speed_rpm_there": round(sized.speed_rpm.value, 1)
        if sized.speed_rpm.point == point
        else None,
        "peak_nm_zero_speed": round(still.peak_nm.value, 4),
        "below_z_mm": round(z_cut * 1e3, 1),
        "peak_nm_below": round(below.peak_nm.value, 4),
        "speed_rpm_below": round(below.speed_rpm.value, 1),
        "passes_below": below.passes,
    }
