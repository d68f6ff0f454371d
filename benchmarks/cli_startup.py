"""Start-up time of the ``deltadash`` command line: ``--help``, ``ik`` and ``fk``.

Usage: python benchmarks/cli_startup.py [--repeat 9]

Each command runs as a fresh subprocess (``python -m app.cli ...``, the same code as the
installed ``deltadash`` script) and the wall time from spawn to exit is taken; the table
gives the median and the best of --repeat runs. The machine's other load only slows a
run down, so the best is the floor and the median what a person typically waits.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
COMMANDS = {
    "deltadash --help": ["--help"],
    "deltadash ik 0 0 -240": ["ik", "0", "0", "-240"],
    "deltadash fk 30 30 30": ["fk", "30", "30", "30"],
}


def _seconds(argv: list[str]) -> float:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    start = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "app.cli", *argv],
        cwd=ROOT,
        env=env,
        check=False,  # a refusal (exit 1 or 2) is timed like a success
        stdout=subprocess.DEVNULL,
    )
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=9)
    args = parser.parse_args()
    _seconds(["--help"])  # warm the file cache and the bytecode
    print(f"{platform.node()} {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs")
    print(f"python {platform.python_version()}, load average {os.getloadavg()[0]:.2f}")
    print("| command | median | best |")
    print("| --- | --- | --- |")
    for name, argv in COMMANDS.items():
        times = [_seconds(argv) for _ in range(args.repeat)]
        print(f"| `{name}` | {statistics.median(times):.3f} s | {min(times):.3f} s |")


if __name__ == "__main__":
    main()
