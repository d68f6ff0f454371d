"""The thesis sinusoid's loop health and tracking, on a headless controller (no HTTP server).

Runs the ch. 6.1 sinusoid (X 5 cm 1 Hz, Y 5 cm 1 Hz, Z 8 cm 2 Hz, no feed-forward) and
prints, per run, the loop health its stats carry (app/runs/health.py: rate, lateness p50 /
p99 / worst, overruns, longest gap between ticks, stale feedback, the verdict and its
reasons) beside the tracking RMSE. Run it on a quiet machine and beside two CPU hogs
(``python3 -c 'while 1: pass' &`` twice): the loaded run must be flagged, the quiet one not.

Usage: python benchmarks/run_health.py [--backend sim] [--duration 10] [--runs 1]
"""

from __future__ import annotations

import argparse
import gc
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
from app.control.errors import MotionRefused  # noqa: E402
from app.runs.health import summary  # noqa: E402
from app.runs.manager import RunManager  # noqa: E402
from app.runs.trajectories import SinusoidParams  # noqa: E402
from app.server.backends import open_backend  # noqa: E402


def start(runs: RunManager, params: SinusoidParams):
    """Start the run once the arm, just held by torque on, has stopped moving (a plan from
    a moving arm is refused: "the robot moved ... since the plan")."""
    for _ in range(50):
        try:
            return runs.start_sinusoid(params)
        except MotionRefused:
            time.sleep(0.2)
    return runs.start_sinusoid(params)


def line(run) -> str:
    h, t = run.stats["health"], run.stats["tracking"]
    late = h["lateness_ms"]
    rmse = " / ".join(f"{t[a]['rmse_m'] * 1e3:.2f}" for a in "xyz")
    return (
        f"{run.state}, {run.samples} ticks | {h['rate_hz']:.1f} Hz | lateness p50 "
        f"{late['p50']:.2f} p99 {late['p99']:.2f} worst {late['worst']:.1f} ms | overruns "
        f"{h['overruns']} ({h['overrun_share']:.2%}) | longest gap {h['longest_gap_ms']:.1f} ms "
        f"| stale {h['stale_ticks']} ticks, longest {h['longest_stale_ms']:.1f} ms | RMSE x/y/z "
        f"{rmse} mm\n  {summary(h)}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--backend", default="sim")
    parser.add_argument("--duration", type=float, default=10.0)
    parser.add_argument("--runs", type=int, default=1)
    args = parser.parse_args()
    sys.setswitchinterval(2.5e-4)  # as the server's lifespan (app/server/app.py) runs its loop
    gc.collect()
    gc.freeze()
    load = " ".join(f"{v:.2f}" for v in os.getloadavg())
    print(f"python {platform.python_version()}, {os.cpu_count()} cores, load {load}")
    settings = load_settings(
        hardware={"backend": args.backend},
        runs={"folder": tempfile.mkdtemp(prefix="deltadash-health-")},
    )
    with open_backend(settings) as opened:
        controller = Controller(settings, opened.bus, opened.kind, opened.description)
        controller.start()
        try:
            controller.set_torque(True).result(timeout=5.0)
            runs = RunManager(controller, settings.runs.folder_path)
            print(f"backend: {opened.description}")
            for _ in range(args.runs):
                before = controller.timing.since_start()
                run = start(runs, SinusoidParams(duration_s=args.duration))
                run.done.wait()
                after = controller.timing.since_start()
                print(line(run))
                print(  # the loop's own counter over the same time, as a cross-check
                    f"  loop timing meanwhile: {after.overruns - before.overruns} overruns "
                    f"in {after.ticks - before.ticks} ticks"
                )
        finally:
            controller.stop()
    print("load after: " + " ".join(f"{v:.2f}" for v in os.getloadavg()))


if __name__ == "__main__":
    main()
