"""CPU time of the G-code dry run (app/programs/dry_run.py) per second of program.

Usage: python benchmarks/gcode_dry_run.py [--repeat 3]

Plays examples/circle.ngc and examples/helix.ngc on the headless twin (the default
config's robot) and prints, per program, its duration, the dry run's process CPU time
(best of --repeat) and the ratio: what ``[programs] dry_run_max_s`` is sized by.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]
sys.path.insert(0, str(_HERE.parent))

from app.config import load_settings  # noqa: E402
from app.programs.check import check_program  # noqa: E402
from app.programs.dry_run import dry_run  # noqa: E402

EXAMPLES = _HERE.parent / "examples"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="best of this many runs")
    args = parser.parse_args()
    settings = load_settings()
    print(f"python {platform.python_version()}, load average {os.getloadavg()[0]:.1f}")
    for name in ("circle.ngc", "helix.ngc"):
        checked = check_program((EXAMPLES / name).read_text(), settings)
        best = float("inf")
        for _ in range(args.repeat):
            began = time.process_time()
            result = dry_run(checked, settings)
            best = min(best, time.process_time() - began)
        duration = checked.path.duration_s
        print(
            f"{name}: {duration:.1f} s of program, dry run {best:.2f} s CPU "
            f"({best / duration * 1e3:.0f} ms per program second, "
            f"{best / (duration * settings.loop.rate_hz) * 1e3:.2f} ms per tick); "
            f"max error {result.max_m * 1e3:.2f} mm"
        )


if __name__ == "__main__":
    main()
