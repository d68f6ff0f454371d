"""``deltadash emulate``: run the servo emulator standalone and print its pty path.

The work is hardware.emulator.serve's (also ``python -m hardware.emulator``); this module
only registers the sub-command on the app's parser.
"""

from __future__ import annotations

import argparse

from hardware.emulator.serve import DESCRIPTION, add_arguments, parse_ids, run

__all__ = ["add_parser", "configure", "parse_ids", "run"]


def configure(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add the emulate options to `parser` and set its handler."""
    add_arguments(parser).set_defaults(handler=run)
    return parser


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``emulate`` on the app's sub-command parsers."""
    parser = subparsers.add_parser(
        "emulate", help="emulate XM430-W210 servos on a pseudo-terminal", description=DESCRIPTION
    )
    return configure(parser)
