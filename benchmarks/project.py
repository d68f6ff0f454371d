"""Cost of one `project()` call: the server's nearest point and the jog clamp.

Usage: python benchmarks/project.py [--goals 2000] [--seed 0]

For each robot and (margin, ceiling), times single calls on three kinds of goal:
- inside: admissible goals (returned unchanged: the check only);
- near: outside goals 0.5-20 mm from an admissible point (what a jog clamp sees);
- far: outside goals anywhere in a box twice the workspace's size (the 422's case).
Prints wall-clock and CPU-time p50 / p99 per call in microseconds, and the first call's
cost (the edges and vertices of the admissible set are computed once per robot, margin
and ceiling, then cached). Prints the load average, which sets the wall-clock tail on a
shared VM.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]

from kinematics import (  # noqa: E402
    THESIS_DELTA,
    LinearDelta,
    projection,  # noqa: E402
)

CASES = [
    ("RotaryDelta (thesis), server settings", THESIS_DELTA, 0.002, -0.06),
    ("RotaryDelta (thesis), no margin or ceiling", THESIS_DELTA, 0.0, None),
    ("LinearDelta (towers), server settings", LinearDelta(l=0.215, R=0.105, r=0.03), 0.002, -0.06),
    (
        "LinearDelta (rails at 60 deg), server settings",
        LinearDelta(l=0.215, R=0.105, r=0.03, incline=math.radians(60)),
        0.002,
        -0.06,
    ),
]


def _admissible(robot, points, margin, z_max):
    ok = robot.reachable(points, margin=margin) if margin > 0 else robot.reachable(points)
    return ok & (points[:, 2] <= z_max) if z_max is not None else ok


def _goals(robot, margin, z_max, count, rng):
    low, high = (-0.6, 1.5) if robot is THESIS_DELTA else (-robot.l, robot.l)
    points, ok = robot.fk(rng.uniform(low, high, (20 * count, 3)))
    inside = points[ok][_admissible(robot, points[ok], margin, z_max)]
    size = robot.l + getattr(robot, "L", 0.0) + robot.R
    box = rng.uniform([-size, -size, -2 * size], [size, size, size], (8 * count, 3))
    far = box[~_admissible(robot, box, margin, z_max)]
    # near: bisect from an inside goal towards a far one onto the boundary, step past it
    a, b = inside[:count], far[:count]
    for _ in range(40):
        middle = 0.5 * (a + b)
        ok = _admissible(robot, middle, margin, z_max)
        a, b = np.where(ok[:, None], middle, a), np.where(ok[:, None], b, middle)
    direction = (far[:count] - inside[:count]) / np.linalg.norm(
        far[:count] - inside[:count], axis=1, keepdims=True
    )
    near = b + direction * rng.uniform(0.0005, 0.02, (count, 1))
    near = near[~_admissible(robot, near, margin, z_max)]
    return {"inside": inside[:count], "near": near, "far": far[:count]}


def _times_us(robot, goals, margin, z_max):
    """Wall-clock and this thread's CPU time per call [us] (the CPU time leaves out the
    waits for a core that other processes cause on a shared machine)."""
    wall, cpu = [], []
    for goal in goals:
        start, start_cpu = time.perf_counter(), time.thread_time()
        robot.project(goal, margin=margin, z_max=z_max)
        cpu.append(time.thread_time() - start_cpu)
        wall.append(time.perf_counter() - start)
    return np.array(wall) * 1e6, np.array(cpu) * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--goals", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    print(f"python {platform.python_version()}, numpy {np.__version__}, {platform.machine()}")
    print(f"load average at start: {os.getloadavg()}")
    for name, robot, margin, z_max in CASES:
        rng = np.random.default_rng(args.seed)
        projection.boundary.cache_clear()
        start = time.perf_counter()
        robot.project([1.0, 1.0, 1.0], margin=margin, z_max=z_max)
        first = (time.perf_counter() - start) * 1e3
        print(f"\n{name} (margin {margin} m, z_max {z_max} m): first call {first:.0f} ms")
        for kind, goals in _goals(robot, margin, z_max, args.goals, rng).items():
            wall, cpu = _times_us(robot, goals, margin, z_max)
            w50, w99 = np.percentile(wall, [50, 99])
            c50, c99 = np.percentile(cpu, [50, 99])
            print(
                f"  {kind:6} n={len(wall):5}  wall p50 {w50:5.0f} p99 {w99:6.0f} us"
                f"  cpu p50 {c50:5.0f} p99 {c99:6.0f} max {cpu.max():6.0f} us"
            )
    print(f"\nload average at end: {os.getloadavg()}")


if __name__ == "__main__":
    main()
