"""``deltadash emulate``: run the servo emulator standalone and print its pty path.

Any Dynamixel client can then open that path as its serial port, e.g. dynamixel-sdk's own
examples with DEVICENAME set to it, or ``DynamixelConfig(port=...)``. Stops on Ctrl-C.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from collections.abc import Sequence
from typing import TextIO

from hardware.dynamixel.control_table import Reg
from hardware.emulator import ServoEmulator


def parse_ids(text: str) -> list[int]:
    """'1,2,3' -> [1, 2, 3]; ids must be 0..252 and distinct."""
    try:
        ids = [int(part) for part in text.split(",") if part.strip()]
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"ids must be integers like 1,2,3: {text!r}") from exc
    if not ids or len(set(ids)) != len(ids) or not all(0 <= i <= 252 for i in ids):
        raise argparse.ArgumentTypeError(f"ids must be distinct, in 0..252: {text!r}")
    return ids


def configure(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add the emulate options to `parser` and set its handler."""
    parser.add_argument(
        "--ids", type=parse_ids, default=[1, 2, 3], help="servo ids, comma separated (1,2,3)"
    )
    parser.add_argument(
        "--return-delay-us",
        type=int,
        default=None,
        help="Return Delay Time of every servo [us] (factory default 500; 0 for speed)",
    )
    parser.add_argument(
        "--model",
        choices=["simple", "twin"],
        default="simple",
        help="motion: a simple position loop per servo, or the MuJoCo twin of the thesis robot",
    )
    parser.set_defaults(handler=run)
    return parser


def _model(name: str, ids: list[int]):
    if name != "twin":
        return None
    from hardware.calibration import JointCalibration
    from hardware.sim import TwinConfig, TwinMotionModel

    if len(ids) != 3:
        raise SystemExit("--model twin drives a 3-leg Delta: give three --ids")
    return TwinMotionModel(TwinConfig(joints=tuple(JointCalibration(i) for i in ids)))


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``emulate`` on the app's sub-command parsers."""
    parser = subparsers.add_parser(
        "emulate", help="emulate XM430-W210 servos on a pseudo-terminal", description=__doc__
    )
    return configure(parser)


def run(
    args: argparse.Namespace, stop: threading.Event | None = None, out: TextIO | None = None
) -> int:
    """Serve until `stop` is set or SIGINT/SIGTERM arrives; prints the pty path to `out`."""
    stop = stop or threading.Event()
    out = out or sys.stdout
    if threading.current_thread() is threading.main_thread():
        # Before the path is printed: a client may signal as soon as it has read it.
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: stop.set())
    with ServoEmulator(
        args.ids, model=_model(getattr(args, "model", "simple"), args.ids)
    ) as emulator:
        if args.return_delay_us is not None:
            units = min(254, max(0, args.return_delay_us) // 2)  # 2 us per unit
            with emulator.lock:
                for servo in emulator.servos:
                    servo.table.set(Reg.RETURN_DELAY_TIME, units)
        ids = ",".join(str(i) for i in args.ids)
        print(emulator.port, file=out, flush=True)
        print(f"XM430-W210 x{len(args.ids)} (ids {ids}) on {emulator.port}", file=sys.stderr)
        stop.wait()
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point: ``python -m hardware.emulator_cli --ids 1,2,3``."""
    parser = configure(argparse.ArgumentParser(prog="deltadash emulate", description=__doc__))
    args = parser.parse_args(argv)
    return args.handler(args)


if __name__ == "__main__":
    sys.exit(main())
