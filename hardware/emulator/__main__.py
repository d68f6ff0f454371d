"""``python -m hardware.emulator --ids 1,2,3``: the servo emulator as its own process."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from hardware.emulator.serve import DESCRIPTION, add_arguments, run


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m hardware.emulator", description=DESCRIPTION)
    return run(add_arguments(parser).parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
