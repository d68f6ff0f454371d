"""What the tuning run's twin check does to the control loop running beside it.

A tuning run checks its candidate gains on the twin (app/tuning/twin_check.py's `offer`:
8-16 candidates, ~20 s of simulated twin each) before it suggests them; the server runs
that check in a worker process (app/tuning/procedure.py's ``_check_in_worker``, one
``ProgramWorkers`` slot, nice +10). This runs a headless controller on the simulator at its
rate, holding torque, and prints the loop's timing (benchmarks/gcode_check_loop.py's
figures: rate, lateness p50 / p99 / worst, overruns, longest gap) over a window with
nothing else to do, then interleaved windows while a thread of this process runs one
candidate's check (`twin_check.check`) again and again, and while a thread waits on a
worker process that does (as the server does).

Usage: python benchmarks/tuning_check_loop.py [--window 10] [--rounds 2]
"""

from __future__ import annotations

import argparse
import gc
import os
import platform
import sys
import tempfile
import threading
import time
from pathlib import Path

_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]
sys.path.insert(0, str(_HERE))  # for gcode_check_loop's windows
sys.path.insert(1, str(_HERE.parent))

from gcode_check_loop import _mean, checking, window  # noqa: E402

from app.config import load_settings  # noqa: E402
from app.control.controller import Controller  # noqa: E402
from app.control.errors import MotionRefused  # noqa: E402
from app.programs.workers import ProgramWorkers  # noqa: E402
from app.server.backends import open_backend  # noqa: E402
from app.tuning.twin_check import check  # noqa: E402
from hardware.bus import PositionGains  # noqa: E402

GAINS = PositionGains(p=1010)  # the set the check offers for the twin's joints


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--window", type=float, default=10.0)
    parser.add_argument("--rounds", type=int, default=2, help="thread / worker window pairs")
    args = parser.parse_args()
    sys.setswitchinterval(2.5e-4)  # as the server's lifespan (app/server/app.py) runs its loop
    gc.collect()
    gc.freeze()
    load = " ".join(f"{v:.2f}" for v in os.getloadavg())
    print(f"python {platform.python_version()}, {os.cpu_count()} cores, load {load}")
    settings = load_settings(runs={"folder": tempfile.mkdtemp(prefix="deltadash-tloop-")})
    with open_backend(settings) as opened:
        controller = Controller(settings, opened.bus, opened.kind, opened.description)
        controller.start()
        try:
            for _ in range(40):  # the relaxed twin swings past a joint limit at first
                try:
                    controller.set_torque(True).result(timeout=5.0)
                    break
                except MotionRefused:
                    time.sleep(0.5)
            print(f"backend: {opened.description}; one candidate's check: {GAINS}")
            busy = threading.Event()
            workers = ProgramWorkers(settings, slots=1, timeout_s=600.0)
            workers.call(check, GAINS)  # the worker started and warm
            window(controller, args.window, "idle (torque on, holding)", busy)
            for _ in range(args.rounds):  # interleaved: the machine's load drifts
                in_thread = checking(
                    controller, args.window, "checking in a thread", busy, lambda: check(GAINS)
                )
                print(f"  {len(in_thread)} checks, {_mean(in_thread):.2f} s each")
                in_worker = checking(
                    controller,
                    args.window,
                    "checking in a worker process",
                    busy,
                    lambda: workers.call(check, GAINS),
                )
                print(f"  {len(in_worker)} checks, {_mean(in_worker):.2f} s each")
            workers.close()
            window(controller, args.window, "idle at the end", busy)
        finally:
            controller.stop()
    print("load after: " + " ".join(f"{v:.2f}" for v in os.getloadavg()))


if __name__ == "__main__":
    main()
