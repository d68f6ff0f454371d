"""Hold-in-world with a tool and a wrist (issue 19) on the MuJoCo twin: the world RMSE of
the tool tip and the world heading error, plain (thesis) and latency compensated, with and
without drone yaw, beside the same holds without [tool]/[wrist].

Usage: python benchmarks/hold_heading.py [--hold 20] [--seed 0] [--yaw 2 10]
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

# benchmarks/kinematics.py would shadow the kinematics package: keep this folder off the path
_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]

from app.config import load_settings  # noqa: E402
from app.control.controller import Controller  # noqa: E402
from app.runs.manager import RunManager  # noqa: E402
from app.server.backends import open_backend  # noqa: E402
from app.world.drone_sim import DroneSimParams  # noqa: E402
from app.world.service import WorldService  # noqa: E402

TOOL = (0.0, 0.0, -0.05)


def _holds(tooled: bool, args: argparse.Namespace) -> None:
    sections = {"tool": {"offset_m": TOOL}, "wrist": {"enabled": True}} if tooled else {}
    settings = load_settings(
        hardware={"backend": "sim"},
        runs={"folder": tempfile.mkdtemp(prefix="deltadash-bench-")},
        # a loaded VM stalls the simulator past the 0.5 s stale-feedback fault: let the
        # runs finish, and print the run's loop health beside the figures
        safety={"stale_feedback_s": args.stale_s},
        **sections,
    )
    label = f"tool {TOOL} + wrist" if tooled else "no tool, no wrist"
    with open_backend(settings) as opened:
        controller = Controller(settings, opened.bus, opened.kind, opened.description)
        controller.start()
        try:
            controller.set_torque(True).result(timeout=10.0)
            runs, world = (
                RunManager(controller, settings.runs.folder_path),
                WorldService(controller),
            )
            tip_z = -0.24 + (TOOL[2] if tooled else 0.0)
            for yaw in args.yaw:
                for compensate in (False, True):
                    # a loaded machine can stall the simulator into a stale-feedback fault
                    controller.reset().result(timeout=10.0)
                    controller.set_torque(True).result(timeout=10.0)
                    controller.set_goal([0.0, 0.0, tip_z]).result(timeout=10.0)
                    time.sleep(1.5)  # let the jog settle so every run starts alike
                    drone = DroneSimParams(seed=args.seed, yaw_deg=yaw)
                    source = world.hold_source(None, world.provider(drone), compensate)
                    source.duration_s = args.hold + source.approach_s
                    run = runs.start_source("hold", {"latency_compensation": compensate}, source)
                    run.done.wait()
                    w = run.stats["world"]
                    rmse = " ".join(f"{w[a]['rmse_m'] * 1e3:5.2f}" for a in "xyz")
                    worst = " / ".join(f"{w[a]['max_abs_m'] * 1e3:.1f}" for a in "xyz")
                    heading = w.get("heading")
                    turn = (
                        f"heading RMSE {math.degrees(heading['rmse_rad']):.3f} deg, max "
                        f"{math.degrees(heading['max_abs_rad']):.3f} deg, limited "
                        f"{heading['limited_s']:.2f} s"
                        if heading
                        else "heading -"
                    )
                    health = run.stats.get("health", {}).get("ok")
                    state = f"{run.state} {run.abort_reason or ''}".strip()
                    print(
                        f"| {label} | yaw {yaw:g} deg | {'compensated' if compensate else 'plain'}"
                        f" | {rmse} | {worst} | {turn} | outside {w['outside_s']:.2f} s"
                        f" | health ok {health}, {state} ({run.run_id}),"
                        f" load {os.getloadavg()[0]:.1f} |",
                        flush=True,
                    )
        finally:
            controller.stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--hold", type=float, default=20.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--yaw", type=float, nargs="+", default=[0.0, 2.0, 10.0])
    parser.add_argument("--stale-s", type=float, default=0.5, help="safety.stale_feedback_s")
    parser.add_argument("--plain-robot", action="store_true", help="also without tool/wrist")
    args = parser.parse_args()
    print(
        f"python {platform.python_version()}, {os.cpu_count()} cores, "
        f"load {os.getloadavg()[0]:.2f} (1 min)",
        flush=True,
    )
    _holds(True, args)
    if args.plain_robot:
        _holds(False, args)
    print(f"load after: {os.getloadavg()[0]:.2f} (1 min)")


if __name__ == "__main__":
    main()
