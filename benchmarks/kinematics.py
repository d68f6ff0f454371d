"""Speed of the kinematics: batch IK/FK in ns/point and single-point calls in us.

Usage: python benchmarks/kinematics.py [--repeat 7]

Prints one table per robot type. Each figure is the best of --repeat runs (the
machine's other load only ever slows a run down). The C reference on the same
machine (same maths, gcc -O2): IK about 40 ns/point, FK about 62 ns/point.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

# This file is named like the package it measures: keep its folder off the import path.
_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]

from kinematics import THESIS_DELTA, LinearDelta  # noqa: E402

PRINTER = LinearDelta(l=0.215, R=0.105, r=0.03)


def _best_seconds(call: Callable[[], object], repeat: int, number: int = 1) -> float:
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(number):
            call()
        best = min(best, (time.perf_counter() - start) / number)
    return best


def _workspace_points(robot, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """n reachable points and their joints, from random joints through FK."""
    low, high = (-0.3, 1.2) if robot is THESIS_DELTA else (-0.05, 0.15)
    joints = rng.uniform(low, high, size=(2 * n, 3))
    points, ok = robot.fk(joints)
    points, joints = points[ok][:n], joints[ok][:n]
    return points, robot.ik(points).joints


def bench(robot, name: str, repeat: int) -> None:
    rng = np.random.default_rng(0)
    print(f"\n{name}: {robot}")
    for n in (1_000_000, 1_000):
        points, joints = _workspace_points(robot, n, rng)
        number = max(1, 100_000 // n)
        ik = _best_seconds(lambda p=points: robot.ik(p), repeat, number) / len(points) * 1e9
        fk = _best_seconds(lambda q=joints: robot.fk(q), repeat, number) / len(joints) * 1e9
        print(f"  batch N={len(points):>9,}  IK {ik:7.1f} ns/point   FK {fk:7.1f} ns/point")
    point, joint = points[0], joints[0]
    for label, arg, call in (("array", point, None), ("tuple", tuple(point.tolist()), None)):
        ik1 = _best_seconds(lambda a=arg: robot.ik(a), repeat, 20_000) * 1e6
        del call
        q = joint if label == "array" else tuple(joint.tolist())
        fk1 = _best_seconds(lambda a=q: robot.fk(a), repeat, 20_000) * 1e6
        near = _best_seconds(lambda a=arg, b=q: robot.ik(a, near=b), repeat, 20_000) * 1e6
        print(f"  single ({label:5})  IK {ik1:5.2f} us  IK+near {near:5.2f} us  FK {fk1:5.2f} us")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeat", type=int, default=7)
    args = parser.parse_args()
    print(f"python {platform.python_version()}, numpy {np.__version__}, {platform.machine()}")
    bench(THESIS_DELTA, "RotaryDelta (thesis)", args.repeat)
    bench(PRINTER, "LinearDelta (vertical towers)", args.repeat)


if __name__ == "__main__":
    main()
