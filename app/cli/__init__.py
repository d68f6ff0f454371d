"""The ``deltadash`` command line."""

from __future__ import annotations

import argparse
import json
import math
import sys

from app.cli import design, home, run, serve
from hardware import emulator_cli
from kinematics import THESIS_DELTA, DeltaError


def _ik(args: argparse.Namespace) -> int:
    point = (args.x, args.y, args.z)
    result = THESIS_DELTA.ik(point)
    payload = {
        "point_m": list(point),
        "ok": bool(result.ok),
        "joints_rad": [None if math.isnan(v) else v for v in result.joints.tolist()],
    }
    if args.json:
        print(json.dumps(payload))
    elif result.ok:
        degrees = ", ".join(f"{math.degrees(v):8.3f}" for v in result.joints)
        mm = f"({args.x * 1e3:.1f}, {args.y * 1e3:.1f}, {args.z * 1e3:.1f}) mm"
        print(f"IK {mm} -> joints [{degrees}] deg")
    else:
        nearest = THESIS_DELTA.project(point).point
        mm = ", ".join(f"{v * 1e3:.1f}" for v in nearest)
        print(f"unreachable: ({args.x}, {args.y}, {args.z}) m; nearest reachable ({mm}) mm")
    return 0 if result.ok else 1


def _fk(args: argparse.Namespace) -> int:
    joints = [math.radians(v) for v in args.joints] if args.deg else list(args.joints)
    result = THESIS_DELTA.fk(joints)
    payload = {
        "joints_rad": joints,
        "ok": bool(result.ok),
        "point_m": [None if math.isnan(v) else v for v in result.points.tolist()],
    }
    if args.json:
        print(json.dumps(payload))
    elif result.ok:
        mm = ", ".join(f"{v * 1e3:8.3f}" for v in result.points)
        print(f"FK -> platform ({mm}) mm")
    else:
        print("no platform position: the three spheres do not meet")
    return 0 if result.ok else 1


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="deltadash", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)
    serve.add_parser(commands)
    run.add_parser(commands)
    design.add_parser(commands)
    home.add_parser(commands)
    emulator_cli.add_parser(commands)
    ik = commands.add_parser("ik", help="inverse kinematics of the thesis robot (metres)")
    ik.add_argument("x", type=float)
    ik.add_argument("y", type=float)
    ik.add_argument("z", type=float)
    ik.add_argument("--json", action="store_true", help="machine-readable output")
    ik.set_defaults(handler=_ik)
    fk = commands.add_parser("fk", help="forward kinematics of the thesis robot (radians)")
    fk.add_argument("joints", type=float, nargs=3)
    fk.add_argument("--deg", action="store_true", help="joint angles given in degrees")
    fk.add_argument("--json", action="store_true", help="machine-readable output")
    fk.set_defaults(handler=_fk)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.handler(args)
    except DeltaError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2

