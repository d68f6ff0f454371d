"""What a long G-code check does to the control loop running beside it.

The server checks a program (POST /api/programs/check, /run, /dry-run) in a worker
process (app/programs/workers.py); it used to check in its thread pool, in the control
loop's process. This runs a headless controller on the simulator at its rate, holding
torque, and prints the loop's timing over a window with nothing else to do, over a window
while a thread of this process checks a long program again and again (the raster of
benchmarks/gcode_check.py; as before), and over one while a worker process does (as now):
rate, lateness p50 / p99 / worst, overruns, longest gap.

Usage: python benchmarks/gcode_check_loop.py [--lines 4000] [--window 10] [--rounds 2]
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
sys.path.insert(0, str(_HERE))  # for the raster program of gcode_check.py

from gcode_check import program  # noqa: E402

from app.config import load_settings  # noqa: E402
from app.control.controller import Controller  # noqa: E402
from app.control.errors import MotionRefused  # noqa: E402
from app.programs.check import check_program  # noqa: E402
from app.programs.workers import CheckJob, ProgramWorkers  # noqa: E402
from app.server.backends import open_backend  # noqa: E402


def window(controller: Controller, seconds: float, what: str, busy: threading.Event) -> None:
    """Wait out ``seconds`` and print the loop's figures over exactly that time."""
    before = controller.timing.since_start()
    time.sleep(seconds)
    after = controller.timing.since_start()
    last = controller.timing.last_window()  # the last 10 s: this window when seconds >= 10
    ticks = after.ticks - before.ticks
    overruns = after.overruns - before.overruns
    print(
        f"{what:<28} {ticks / seconds:7.1f} Hz  lateness p50 {last.jitter_p50_ms:5.2f} "
        f"p99 {last.jitter_p99_ms:6.2f} worst {last.worst_ms:6.1f} ms  overruns {overruns} "
        f"({100 * overruns / max(ticks, 1):.1f} %)  longest gap {last.longest_gap_ms:.1f} ms"
        + f"  load {os.getloadavg()[0]:.1f}"
        + ("  [checking]" if busy.is_set() else "")
    )


def _mean(values: list[float]) -> float:
    return sum(values) / max(len(values), 1)


def checking(
    controller: Controller, seconds: float, what: str, busy: threading.Event, check
) -> list[float]:
    """One window while a thread calls ``check()`` again and again; each call's time [s]."""
    stop, times = threading.Event(), []

    def again() -> None:
        busy.set()
        while not stop.is_set():
            begin = time.perf_counter()
            check()
            times.append(time.perf_counter() - begin)
        busy.clear()

    worker = threading.Thread(target=again, daemon=True)
    worker.start()
    window(controller, seconds, what, busy)
    stop.set()
    worker.join()
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lines", type=int, default=4000)
    parser.add_argument("--window", type=float, default=10.0)
    parser.add_argument("--rounds", type=int, default=2, help="thread / worker window pairs")
    args = parser.parse_args()
    sys.setswitchinterval(2.5e-4)  # as the server's lifespan (app/server/app.py) runs its loop
    gc.collect()
    gc.freeze()
    load = " ".join(f"{v:.2f}" for v in os.getloadavg())
    print(f"python {platform.python_version()}, {os.cpu_count()} cores, load {load}")
    settings = load_settings(runs={"folder": tempfile.mkdtemp(prefix="deltadash-gloop-")})
    text = program(args.lines)
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
            check_program(text, settings, gate=controller.gate)  # warm-up (workspace cache)
            print(f"backend: {opened.description}; program: {args.lines} lines")
            busy = threading.Event()
            workers = ProgramWorkers(settings, slots=1, timeout_s=600.0)
            job = CheckJob(text, settings, gate=controller.gate)
            workers.check(job)  # the worker started and warm, as after a server's first check
            window(controller, args.window, "idle (torque on, holding)", busy)
            for _ in range(args.rounds):  # interleaved: the machine's load drifts
                in_thread = checking(
                    controller,
                    args.window,
                    "checking in a thread",
                    busy,
                    lambda: check_program(text, settings, gate=controller.gate),
                )
                print(f"  {len(in_thread)} checks, {_mean(in_thread):.2f} s each")
                in_worker = checking(
                    controller,
                    args.window,
                    "checking in a worker process",
                    busy,
                    lambda: workers.check(job),
                )
                print(f"  {len(in_worker)} checks, {_mean(in_worker):.2f} s each")
            workers.close()
            window(controller, args.window, "idle at the end", busy)
        finally:
            controller.stop()
    print("load after: " + " ".join(f"{v:.2f}" for v in os.getloadavg()))


if __name__ == "__main__":
    main()
