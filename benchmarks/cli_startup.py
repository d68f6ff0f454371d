"""Start-up time of the ``deltadash`` command line: ``--help``, ``ik`` and ``fk``.

Usage: python benchmarks/cli_startup.py [--repeat 9] [--root OTHER_CHECKOUT ...]

Each command runs as a fresh subprocess (``python -m app.cli ...``, the same code as the
installed ``deltadash`` script) and the wall time from spawn to exit is taken, with the
child's CPU time (user + system, less sensitive to the machine's other load); the table
gives the median and the best of --repeat runs. With --root the same commands run from
other checkouts too (e.g. a worktree of the commit before a change), interleaved run by
run so that the machine's load falls on each alike.
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
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
# The same questions in the units of the CLI before issue 17 (ik in metres, fk in radians
# unless --deg), for --root checkouts of that time (--legacy-units).
LEGACY = {
    "deltadash ik 0 0 -240": ["ik", "0", "0", "-0.24"],
    "deltadash fk 30 30 30": ["fk", "30", "30", "30", "--deg"],
}


def _cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _seconds(argv: list[str], root: Path = ROOT) -> tuple[float, float]:
    """(wall, CPU) seconds of one ``python -m app.cli ARGV`` run from ``root``."""
    env = {**os.environ, "PYTHONPATH": str(root)}
    cpu, start = _cpu(), time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "app.cli", *argv],
        cwd=root,
        env=env,
        check=False,  # a refusal (exit 1 or 2) is timed like a success
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    return time.perf_counter() - start, _cpu() - cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=9)
    parser.add_argument("--root", type=Path, action="append", default=[], help="other checkout")
    parser.add_argument(
        "--legacy-units", action="store_true", help="--root checkouts predate ik/fk in mm, deg"
    )
    args = parser.parse_args()
    roots = [ROOT, *(r.resolve() for r in args.root)]
    for root in roots:
        _seconds(["--help"], root)  # warm the file cache and the bytecode
    print(f"{platform.node()} {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs")
    print(f"python {platform.python_version()}, load average {os.getloadavg()[0]:.2f}")
    print("| checkout | command | wall median | wall best | CPU median | CPU best |")
    print("| --- | --- | --- | --- | --- | --- |")
    for name, argv in COMMANDS.items():
        runs: dict[Path, list[tuple[float, float]]] = {root: [] for root in roots}
        for _ in range(args.repeat):
            for root in roots:
                legacy = args.legacy_units and root != ROOT
                runs[root].append(_seconds(LEGACY.get(name, argv) if legacy else argv, root))
        for root in roots:
            wall, cpu = zip(*runs[root], strict=True)
            print(
                f"| {root.name} | `{name}` | {statistics.median(wall):.3f} s | {min(wall):.3f} s "
                f"| {statistics.median(cpu):.3f} s | {min(cpu):.3f} s |"
            )
    print(f"load average at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
