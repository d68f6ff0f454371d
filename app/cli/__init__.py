"""The ``deltadash`` command line: one module per sub-command in this package.

``serve`` (serve.py), ``run`` (run.py), ``runs`` (runs.py), ``design`` (design/), ``home``
(home.py), ``ik`` and ``fk`` (kinematics.py); ``emulate`` (emulate.py).
"""

from __future__ import annotations

import argparse
import sys

from app.cli import design, emulate, home, kinematics, run, runs, serve
from kinematics import DeltaError


def build_parser() -> argparse.ArgumentParser:
    description = "The ``deltadash`` command line."
    parser = argparse.ArgumentParser(prog="deltadash", description=description)
    commands = parser.add_subparsers(dest="command", required=True)
    serve.add_parser(commands)
    run.add_parser(commands)
    runs.add_parser(commands)
    design.add_parser(commands)
    home.add_parser(commands)
    emulate.add_parser(commands)
    kinematics.add_parsers(commands)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.handler(args)
    except DeltaError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
