"""``deltadash ik`` and ``deltadash fk``: the thesis robot's kinematics from the command line."""

from __future__ import annotations

import argparse
import json
import math

from kinematics import THESIS_DELTA


def add_parsers(commands: argparse._SubParsersAction) -> None:
    """Register ``ik`` and ``fk`` on the app's sub-command parsers."""
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
