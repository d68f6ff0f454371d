"""Time of the G-code check (app/programs/check.py) on a long program.

Usage: python benchmarks/gcode_check.py [--lines 10000] [--repeat 3]

The program: a raster of short feed moves (5 mm at 50 mm/s, every tenth line a 5 mm
radius half-circle, every fiftieth a 0.05 s dwell) over a 60 mm square at z = -240 mm,
all inside the thesis robot's workspace, so every check runs on every sample (no early
exit). Prints the time per stage (tokenize + modal machine, planning, sampling, the
checks) and in all, per 1,000 lines. The default config's robot and limits; the Gate is
built once beforehand (its first workspace projection is a one-off cost of the server).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]

from app.config import load_settings  # noqa: E402
from app.control.commands import CommandContext  # noqa: E402
from app.programs.check import check_program, plan_limits, verify_limits  # noqa: E402
from app.programs.modal import interpret  # noqa: E402
from app.programs.planner import plan_program  # noqa: E402
from app.programs.tokens import tokenize  # noqa: E402
from app.programs.verify import verify_path  # noqa: E402


def program(lines: int) -> str:
    out = ["G21 G90 G17 G0 X-30 Y-30 Z-240", "F3000"]
    x, y, direction = -30.0, -30.0, 1.0
    while len(out) < lines:
        k = len(out)
        if k % 50 == 0:
            out.append("G4 P0.05")
        elif k % 10 == 0 and -25 <= y <= 20:
            out.append(f"G{2 if direction > 0 else 3} X{x:.3f} Y{y + 10:.3f} R5")
            y += 10
            direction = -direction
        else:
            x_next = x + 5 * direction
            if not -30 <= x_next <= 30:
                y = -30.0 if y + 2 > 30 else y + 2
                out.append(f"G1 Y{y:.3f}")
                direction = -direction
            else:
                x = x_next
                out.append(f"G1 X{x:.3f}")
    return "\n".join(out[:lines])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lines", type=int, default=10_000)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    settings = load_settings()
    gate = CommandContext.from_settings(settings).gate
    text = program(args.lines)
    print(
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"python {platform.python_version()}, numpy {np.__version__}"
    )
    best: dict[str, float] = {}
    for _ in range(args.repeat):
        marks = [time.perf_counter()]
        parsed = interpret(tokenize(text), settings.programs.start_m, (0.0, 0.0, 0.0))
        marks.append(time.perf_counter())
        limits = plan_limits(settings)
        path = plan_program(parsed.segments, limits)
        marks.append(time.perf_counter())
        times = path.sample_times(limits.period_s)
        points, velocity, acceleration = path.evaluate(times, (0, 1, 2))
        lines = path.line_at(times)
        marks.append(time.perf_counter())
        result = verify_path(
            gate, verify_limits(settings), times, lines, points, velocity, acceleration,
            np.full(3, np.nan), limits.period_s,
        )  # fmt: skip
        marks.append(time.perf_counter())
        report = check_program(text, settings, gate=gate).report
        marks.append(time.perf_counter())
        stages = ("parse", "plan", "sample", "verify", "check_program")
        for name, start, end in zip(stages, marks[:-1], marks[1:], strict=True):
            best[name] = min(best.get(name, np.inf), end - start)
    assert report.ok and not result.violations, report.violations[:3]
    per_k = 1000.0 / args.lines
    print(
        f"{args.lines} lines, {len(parsed.segments)} segments, {report.samples} samples "
        f"({report.duration_s:.0f} s of motion at {1 / limits.period_s:.0f} Hz)"
    )
    for name, value in best.items():
        print(f"  {name:14s} {value:7.3f} s   {value * per_k:6.3f} s per 1,000 lines")


if __name__ == "__main__":
    main()
