"""``deltadash home``: the guided homing procedure, saving the joint offsets to the config.

Torque goes off; the operator places the upper links at a known pose (a horizontal jig is
0 deg for every joint; hard stops give a known angle) and presses Enter; the tool reads the
raw positions, computes each joint's zero offset and writes ``[[hardware.joints]]`` into the
config file (other sections are kept). ``--yes`` skips the prompt (scripts, tests).

A joint range the servo cannot reach in its operating mode (one that crosses the
encoder's 0/4095 seam in Position Control Mode) is refused and nothing is saved; the
message names the servo and the fix (docs/hardware.md, "How homing avoids the seam").
"""

from __future__ import annotations

import argparse
import math
import sys

from app.cli.numbers import number


def add_parser(commands: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser = commands.add_parser(
        "home", help="home the joints and save their zero offsets", description=__doc__
    )
    parser.add_argument("--config", required=True, help="TOML config to update (created)")
    parser.add_argument("--port", help="serial port (default from the config)")
    parser.add_argument("--baud", type=int, help="baud rate (default from the config)")
    parser.add_argument(
        "--angles-deg",
        type=number,
        nargs=3,
        default=[0.0, 0.0, 0.0],
        metavar=("J1", "J2", "J3"),
        help="the pose's joint angles (0 = jig)",
    )
    parser.add_argument("--yes", action="store_true", help="do not wait for Enter")
    parser.set_defaults(handler=run)
    return parser


def run(args: argparse.Namespace) -> int:
    from app.config import ConfigError, load_settings
    from hardware.dynamixel.driver import DynamixelBus, DynamixelConfig
    from hardware.errors import BusError, CalibrationError
    from hardware.homing import home_bus

    try:
        overrides = {k: v for k, v in (("port", args.port), ("baud", args.baud)) if v}
        settings = load_settings(args.config if _exists(args.config) else None, hardware=overrides)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    hw = settings.hardware
    try:
        # the legs only: a wrist's zero is its own (docs/hardware.md, "The wrist")
        joints = tuple(joint.calibration() for joint in settings.hardware.joints)
    except CalibrationError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    bus = DynamixelBus(DynamixelConfig(joints=joints, port=hw.port, baudrate=hw.baud))
    confirm = (lambda prompt: print(prompt)) if args.yes else input
    try:
        bus.connect(verify_calibration=False)  # the calibration is what homing replaces
        homed = home_bus(bus, args.config, [math.radians(a) for a in args.angles_deg], confirm)
    except (BusError, CalibrationError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    finally:
        bus.disconnect()
    for joint in homed:
        print(
            f"servo {joint.servo_id}: zero offset {joint.zero_offset_ticks} ticks, "
            f"direction {joint.direction:+d}"
        )
    print(f"saved to {args.config}")
    return 0


def _exists(path: str) -> bool:
    from pathlib import Path

    return Path(path).exists()
