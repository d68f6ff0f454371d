"""The servos' absolute encoder: how many ticks make a revolution, and a tick in radians.

Calibration's tick <-> radian mapping (hardware/calibration.py) rests on these, and the
control table (hardware/dynamixel/control_table.py) counts its position registers in them.
"""

from __future__ import annotations

import math

TICKS_PER_REV = 4096  # XM430-W210: 12-bit absolute encoder
RAD_PER_TICK = 2.0 * math.pi / TICKS_PER_REV
