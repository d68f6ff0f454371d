"""Simulator speed: simulated seconds per wall second at a 1 kHz physics step.

Usage: python benchmarks/sim.py [--seconds 10] [--repeats 3]

Three cases on the thesis design: the mechanism alone (constant torques, servos bypassed),
the twin holding a pose (mechanism + three XM430-W210 models every step), and the twin
tracking the thesis sinusoid with goals from IK at 200 Hz (what a headless run does).
Prints the best and median of `repeats` runs and the machine's load, since the figure is
only as good as the CPU it got.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hardware.dynamixel.control_table import RAD_PER_TICK  # noqa: E402
from hardware.sim.twin import DeltaTwin, hold_command  # noqa: E402
from kinematics import THESIS_DELTA  # noqa: E402


def sinusoid(t: float) -> np.ndarray:
    w = 2.0 * np.pi
    return np.array([0.05 * np.sin(w * t), 0.05 * np.cos(w * t), -0.24 + 0.08 * np.sin(2 * w * t)])


def mechanism_only(twin: DeltaTwin, seconds: float) -> None:
    twin.step_torques([-0.07, -0.07, -0.07], round(seconds / twin.model.opt.timestep))


def holding(twin: DeltaTwin, seconds: float) -> None:
    twin.advance(seconds)


def tracking(twin: DeltaTwin, seconds: float) -> None:
    q = THESIS_DELTA.ik(sinusoid(0.0)).joints
    for k in range(round(seconds * 200)):
        q = THESIS_DELTA.ik(sinusoid(k / 200), near=q).joints
        ticks = np.round(twin.shafts_of_joints(q) / RAD_PER_TICK)
        twin.set_commands([hold_command(float(t * RAD_PER_TICK)) for t in ticks])
        twin.step(5)


def measure(case, seconds: float, repeats: int) -> list[float]:
    speeds = []
    for _ in range(repeats):
        twin = DeltaTwin()
        if case is tracking:
            twin.reset(THESIS_DELTA.ik(sinusoid(0.0)).joints)
        start = time.perf_counter()
        case(twin, seconds)
        speeds.append(twin.time_s / (time.perf_counter() - start))
    return speeds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="simulated s per run")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    print(f"python {platform.python_version()}, {os.cpu_count()} cpus, load {os.getloadavg()}")
    print(f"1 kHz physics, {args.seconds:g} simulated s per run, {args.repeats} runs")
    print(f"{'case':<34}{'best x real time':>18}{'median':>10}")
    for name, case in (
        ("mechanism only (servos bypassed)", mechanism_only),
        ("twin holding (servo models)", holding),
        ("twin tracking sinusoid (IK 200 Hz)", tracking),
    ):
        speeds = measure(case, args.seconds, args.repeats)
        print(f"{name:<34}{max(speeds):>18.1f}{statistics.median(speeds):>10.1f}")
    print(f"load after {os.getloadavg()}")


if __name__ == "__main__":
    main()
