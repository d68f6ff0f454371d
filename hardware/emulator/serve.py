"""Run the servo emulator standalone: open the pty, print its path, serve until stopped.

Any Dynamixel client can then open that path as its serial port, e.g. dynamixel-sdk's own
examples with DEVICENAME set to it, or ``DynamixelConfig(port=...)``. Used by
``python -m hardware.emulator`` and by ``deltadash emulate``; stops on Ctrl-C or SIGTERM.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from collections.abc import Sequence
from typing import TextIO

from hardware.dynamixel.control_table import Reg
from hardware.emulator.pty_transport import ServoEmulator
from hardware.shaft_motion import MotionModel

DESCRIPTION = __doc__


def parse_ids(text: str) -> list[int]:
    """'1,2,3' -> [1, 2, 3]; ids must be 0..252 and distinct."""
    try:
        ids = [int(part) for part in text.split(",") if part.strip()]
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"ids must be integers like 1,2,3: {text!r}") from exc
    if not ids or len(set(ids)) != len(ids) or not all(0 <= i <= 252 for i in ids):
        raise argparse.ArgumentTypeError(f"ids must be distinct, in 0..252: {text!r}")
    return ids


def add_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add the emulator's options (--ids, --return-delay-us, --model) to `parser`."""
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
        help="motion: a simple position loop per servo, or the MuJoCo twin of the thesis robot "
        "(three ids; a fourth is a wrist on its platform)",
    )
    return parser


def shaft_motion(name: str, ids: Sequence[int]) -> MotionModel | None:
    """The motion model named on the command line (None: the emulator's simple default)."""
    if name != "twin":
        return None
    # Only here: the twin needs MuJoCo, and it is the sim room's model of the emulator's shafts.
    from hardware.calibration import JointCalibration
    from hardware.sim import TwinConfig, TwinMotionModel

    if len(ids) not in (3, 4):
        raise SystemExit(
            "--model twin drives a 3-leg Delta: give three --ids (a fourth is its wrist)"
        )
    return TwinMotionModel(TwinConfig(joints=tuple(JointCalibration(i) for i in ids)))


def serve(
    ids: Sequence[int],
    model: MotionModel | None = None,
    return_delay_us: int | None = None,
    stop: threading.Event | None = None,
    out: TextIO | None = None,
) -> int:
    """Serve until `stop` is set or SIGINT/SIGTERM arrives; prints the pty path to `out`."""
    stop = stop or threading.Event()
    out = out or sys.stdout
    if threading.current_thread() is threading.main_thread():
        # Before the path is printed: a client may signal as soon as it has read it.
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: stop.set())
    with ServoEmulator(ids, model=model) as emulator:
        if return_delay_us is not None:
            units = min(254, max(0, return_delay_us) // 2)  # 2 us per unit
            with emulator.lock:
                for servo in emulator.servos:
                    servo.table.set(Reg.RETURN_DELAY_TIME, units)
        listed = ",".join(str(i) for i in ids)
        print(emulator.port, file=out, flush=True)
        print(f"XM430-W210 x{len(ids)} (ids {listed}) on {emulator.port}", file=sys.stderr)
        stop.wait()
    return 0


def run(
    args: argparse.Namespace, stop: threading.Event | None = None, out: TextIO | None = None
) -> int:
    """Serve with the options `add_arguments` parsed."""
    model = shaft_motion(getattr(args, "model", "simple"), args.ids)
    return serve(args.ids, model, args.return_delay_us, stop, out)
