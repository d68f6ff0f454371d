"""The ``deltadash`` command line: one module per sub-command in this package.

``serve`` (serve.py), ``robot`` (robot.py), ``run`` (run.py), ``runs`` (runs.py),
``design`` (design/), ``home`` (home.py), ``ik`` and ``fk`` (kinematics.py); ``emulate``
(emulate.py); ``gcode`` (gcode.py); ``calibrate`` (calibrate.py); ``tune`` (tune.py);
``touch`` (touch.py).

Building the parser imports no heavy library (fastapi, uvicorn, mujoco, matplotlib, scipy,
viser, pydantic): each handler imports what it needs, so ``deltadash --help``, ``ik`` and
``fk`` start fast (benchmarks/cli_startup.py; tests/app/cli/test_help.py checks the law).
"""

from __future__ import annotations

import argparse
import os
import sys

from app.cli import (
    calibrate,
    design,
    emulate,
    gcode,
    home,
    kinematics,
    robot,
    run,
    runs,
    serve,
    touch,
    tune,
)
from app.cli.numbers import allow_negative_numbers
from kinematics import DeltaError

DESCRIPTION = """\
Teleoperate and test a Delta robot: the control server and its dashboard page, test
runs, design tools, a servo emulator and the kinematics. ik and fk speak mm and degrees
(--si for metres and radians); the other commands give each option's unit in their
help; the API and every --json output are SI (m, rad, s). A decimal comma is read as a
decimal point everywhere (10,5 is 10.5), as on the page."""

EPILOG = """\
examples:
  deltadash serve                          dashboard and API on http://127.0.0.1:8000
  deltadash run sinusoid --duration 5      the thesis tracking test on the simulator
  deltadash ik 0 0 -240                    joint angles for the point (0, 0, -240) mm
  deltadash fk 30 30 30                    platform point for joint angles in degrees
  deltadash design size                    motor sizing, and why it differs from the thesis
  deltadash gcode check examples/circle.ngc  a G-code program checked offline
  deltadash touch --direction 0,0,-1 --force 2  touch a surface on a running server

Run "deltadash COMMAND --help" for a command's options."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="deltadash",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    commands = parser.add_subparsers(
        dest="command", required=True, title="commands", metavar="COMMAND"
    )
    serve.add_parser(commands)
    robot.add_parser(commands)
    run.add_parser(commands)
    runs.add_parser(commands)
    design.add_parser(commands)
    home.add_parser(commands)
    emulate.add_parser(commands)
    gcode.add_parser(commands)
    calibrate.add_parser(commands)
    tune.add_parser(commands)
    touch.add_parser(commands)
    kinematics.add_parsers(commands)
    allow_negative_numbers(parser)  # -0,5 and -2e-3 are values, as -5 is
    return parser


SIGPIPE_EXIT = 141  # 128 + SIGPIPE: what a Unix tool whose reader left exits with


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        code = args.handler(args)
        sys.stdout.flush()  # here, not at exit: a reader gone (`| head`) is caught below
        return code
    except DeltaError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # `deltadash gcode check FILE | head`: the reader left; no more
        # output and no traceback (the interpreter's flush at exit would raise it again)
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return SIGPIPE_EXIT
