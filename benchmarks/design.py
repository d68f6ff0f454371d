"""Time and result of the geometric synthesis (thesis problem) over seeds; sizing figures.

Usage: python benchmarks/design.py [--seeds 5] [--popsize 40] [--maxiter 300]

One line per seed: wall time, designs evaluated, (L, l, Rbar, H) in mm, power of point,
certified containment. Then the thesis robot's sizing over regions of its cube. The
machine is shared: read the times as an upper bound (best and median printed).
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

# benchmarks/kinematics.py shadows the package: keep this folder off the import path.
_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]

from kinematics import THESIS_DELTA  # noqa: E402
from kinematics.dynamics import THESIS_MASS  # noqa: E402
from kinematics.sizing import region_grid, size_motors  # noqa: E402
from kinematics.synthesis import THESIS_DESIGN, Problem, score, synthesize  # noqa: E402

REGIONS = {
    "20 cm cube centred at z = -190.3 mm": ([-0.1, -0.1, -0.2903], [0.1, 0.1, -0.0903]),
    "same cube, z <= -150 mm": ([-0.1, -0.1, -0.2903], [0.1, 0.1, -0.15]),
    "same cube, z <= -200 mm": ([-0.1, -0.1, -0.2903], [0.1, 0.1, -0.2]),
    "10 cm cube centred at z = -230 mm": ([-0.05, -0.05, -0.28], [0.05, 0.05, -0.18]),
}


def _synthesis(args: argparse.Namespace) -> None:
    problem = Problem()
    thesis = score(problem, np.array(THESIS_DESIGN))
    print(
        f"thesis Table 4.3: power of point {thesis.power_of_point:.5f} m^4, "
        f"{int(thesis.violations)} violated (sample, leg) pairs"
    )
    times, cpu = [], []
    for seed in range(args.seeds):
        start, start_cpu = time.perf_counter(), time.process_time()
        result = synthesize(problem, popsize=args.popsize, maxiter=args.maxiter, seed=seed)
        times.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
        mm = ", ".join(f"{v * 1e3:.1f}" for v in result.design)
        print(
            f"seed {seed}: {times[-1]:.2f} s (cpu {cpu[-1]:.2f} s), {result.evaluations} "
            f"designs, ({mm}) mm, "
            f"PoP {result.power_of_point:.5f}, contains {result.contains}"
        )
    print(
        f"wall best {min(times):.2f} s, median {statistics.median(times):.2f} s; "
        f"cpu median {statistics.median(cpu):.2f} s"
    )


def _sizing() -> None:
    for name, (lower, upper) in REGIONS.items():
        sized = size_motors(THESIS_DELTA, THESIS_MASS, region_grid(lower, upper, 9))
        print(
            f"{name}: static {sized.static_nm.value:.3f} N m, peak {sized.peak_nm.value:.3f} "
            f"N m, speed {sized.speed_rpm.value:.1f} rpm, XM430-W210 12 V "
            f"{'PASS' if sized.passes else 'FAIL'} (torque x{sized.torque_margin:.2f}, "
            f"speed x{sized.speed_margin:.2f})"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--popsize", type=int, default=40)
    parser.add_argument("--maxiter", type=int, default=300)
    args = parser.parse_args()
    print(
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}, load {os.getloadavg()[0]:.2f}"
    )
    _synthesis(args)
    _sizing()


if __name__ == "__main__":
    main()
