"""Arguments and output shared by the ``deltadash design`` sub-commands."""

from __future__ import annotations

import argparse
import json
from typing import Any

from app.cli.numbers import number
from kinematics import RotaryDelta
from kinematics.dynamics import THESIS_MASS, MassModel


def common(parser: argparse.ArgumentParser, robot: bool = True) -> None:
    if robot:
        group = parser.add_argument_group("robot geometry [m] (default: thesis eq. 4.11)")
        group.add_argument("--L", type=number, default=0.1558, help="upper link length")
        group.add_argument("--l", type=number, default=0.2430, help="parallelogram length")
        group.add_argument("--R", type=number, default=0.0844, help="base radius to motor axis")
        group.add_argument("--r", type=number, default=0.038, help="platform radius")
    parser.add_argument("--json", action="store_true", help="print JSON only")


def mass_args(parser: argparse.ArgumentParser) -> None:
    m = THESIS_MASS
    group = parser.add_argument_group("masses (default: thesis ch. 4.2)")
    group.add_argument("--payload", type=number, default=0.2, help="payload [kg] (0.2)")
    group.add_argument(
        "--platform-kg",
        type=number,
        default=m.platform_kg,
        help="platform without payload [kg] (0.025)",
    )
    group.add_argument("--upper-kg", type=number, default=m.upper_kg, help="upper link [kg]")
    group.add_argument(
        "--upper-inertia",
        type=number,
        default=m.upper_inertia_kgm2,
        help="upper link + reflected rotor about the motor axis [kg m^2] "
        f"({m.upper_inertia_kgm2:.3g}, see kinematics/dynamics.py)",
    )
    group.add_argument(
        "--lower-kg",
        type=number,
        default=m.lower_kg,
        help="one leg's lower link, 2 rods + 4 ball joints [kg] (0.021)",
    )


def robot_from(args: argparse.Namespace) -> RotaryDelta:
    return RotaryDelta(L=args.L, l=args.l, R=args.R, r=args.r)


def mass_from(args: argparse.Namespace) -> MassModel:
    return MassModel(args.platform_kg, args.upper_kg, args.upper_inertia, args.lower_kg)


def emit(args: argparse.Namespace, payload: dict[str, Any], text: str) -> None:
    print(json.dumps(payload) if args.json else text)
