"""Figures of the test runs, on a headless controller (no HTTP server):

- the thesis tracking test (ch. 6.1 sinusoid) with and without feed-forward, beside
  thesis Table 6.1 (RMSE 8.1, 8.7, 14.7 mm);
- the MAV compensation routine (ch. 6.2) on the simulated drone, plain vs latency
  compensated, beside thesis Table 6.3 (RMSE 14.8, 5.3, 3.8 mm).

Usage: python benchmarks/runs.py [--backend emulated] [--duration 10] [--hold 20] [--seed 0]
"""

from __future__ import annotations

import argparse
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
from app.runs.trajectories import SinusoidParams  # noqa: E402
from app.server.backends import open_backend  # noqa: E402
from app.world.drone_sim import DroneSimParams  # noqa: E402
from app.world.service import WorldService  # noqa: E402

THESIS_TRACKING_MM = (8.081, 8.716, 14.721)
THESIS_HOLD_MM = (14.773, 5.267, 3.776)


def _row(label: str, stats: dict, extra: str = "") -> str:
    rmse = " ".join(f"{stats[a]['rmse_m'] * 1e3:7.2f}" for a in "xyz")
    worst = " ".join(f"{stats[a]['max_abs_m'] * 1e3:7.2f}" for a in "xyz")
    return f"  {label:34} RMSE x y z [mm] {rmse}   max {worst} {extra}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--backend", default="emulated")
    parser.add_argument("--duration", type=float, default=10.0)
    parser.add_argument("--hold", type=float, default=20.0)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    print(
        f"python {platform.python_version()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}"
    )
    settings = load_settings(
        hardware={"backend": args.backend},
        runs={"folder": tempfile.mkdtemp(prefix="deltadash-bench-")},
    )
    with open_backend(settings) as opened:
        controller = Controller(settings, opened.bus, opened.kind, opened.description)
        controller.start()
        try:
            controller.set_torque(True).result(timeout=2.0)
            runs, world = (
                RunManager(controller, settings.runs.folder_path),
                WorldService(controller),
            )
            print(f"backend: {opened.description}")
            print(
                "thesis Table 6.1 (real robot)          RMSE x y z [mm] "
                + " ".join(f"{v:7.2f}" for v in THESIS_TRACKING_MM)
            )
            for feedforward in (False, True):
                run = runs.start_sinusoid(
                    SinusoidParams(duration_s=args.duration, feedforward=feedforward)
                )
                run.done.wait()
                print(
                    _row(
                        f"sinusoid, feed-forward {feedforward}",
                        run.stats["tracking"],
                        f"({run.run_id}, {run.samples} ticks)",
                    )
                )
            print(
                "thesis Table 6.3 (real drone)          RMSE x y z [mm] "
                + " ".join(f"{v:7.2f}" for v in THESIS_HOLD_MM)
            )
            for compensate in (False, True):
                controller.set_goal([0.0, 0.0, -0.24]).result(timeout=2.0)
                time.sleep(1.5)  # let the jog settle so both runs start alike
                source = world.hold_source(
                    None, world.provider(DroneSimParams(seed=args.seed)), compensate
                )
                source.duration_s = args.hold + source.approach_s
                run = runs.start_source("hold", {"latency_compensation": compensate}, source)
                run.done.wait()
                w = run.stats["world"]
                print(
                    _row(
                        f"hold, compensation {compensate}",
                        w,
                        f"outside {w['outside_s']:.2f} s ({run.run_id})",
                    )
                )
        finally:
            controller.stop()


if __name__ == "__main__":
    main()
