"""The encoder's seam: which Present Positions a servo can reach in its operating mode.

The XM430's absolute encoder counts one turn, 0 .. 4095 ticks; between 4095 and 0 lies the
seam, a fixed place on the shaft. The ROBOTIS e-Manual (X series, Homing Offset (20) and
Present Position (132)):

    Present Position = Actual Position + Homing Offset

where Actual Position counts on across the seam while torque is off or the servo is in a
multi-turn mode, and is reset to its one-turn value 0 .. 4095 when torque comes on in
Position Control Mode (3), when the Operating Mode changes, and at power-on (or reboot).
The offset is added after that reset (a report on the ROBOTIS forum, firmware 49: Homing
Offset -512, a shaft held at 3700 reads -396 after torque off and on), so **the Homing
Offset renames positions but does not move the seam**. Position Control Mode also bounds
Goal Position by Min/Max Position Limit (48, 52), 0 .. 4095, and ignores a Homing Offset
outside -1024 .. 1024. Hence:

- Position Control Mode: a joint can be held only at Present Positions in
  [max(0, H), min(4095, 4095 + H)] (H the Homing Offset in force); a joint range that
  crosses the seam cannot be reached, whatever H is. The fix is mechanical (turn the link
  on its horn so the range lies inside one turn) or Extended Position Control Mode.
- Extended Position (4) and Current-based Position (5) Control Mode: goals span +-256
  turns and the count crosses the seam freely while powered; at power-on the count is
  one turn again, so a joint whose range crosses the seam may come up one turn (4096
  ticks) away from its calibration. A Homing Offset of H + 4096 k puts it back on its
  calibrated turn: `turn_correction` gives k (hardware/dynamixel/driver.py applies it
  at connect).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from hardware.bus import OperatingMode
from hardware.calibration import JointCalibration
from hardware.encoder import RAD_PER_TICK, TICKS_PER_REV
from hardware.errors import CalibrationError

POSITION_MODE_HOMING_OFFSET_LIMIT = 1024  # Position Control Mode ignores larger |offsets|
POSITION_LIMIT_RANGE = (0, TICKS_PER_REV - 1)  # Min/Max Position Limit (48, 52)
GOAL_POSITION_RANGE = (-1_048_575, 1_048_575)  # Goal Position (116) in multi-turn modes
MULTI_TURN_MODES = frozenset(
    {OperatingMode.EXTENDED_POSITION, OperatingMode.CURRENT_BASED_POSITION}
)


class SeamError(CalibrationError):
    """A joint's range cannot be reached in the servo's operating mode (names the servo,
    the joint, the ticks and the fix)."""


@dataclass(frozen=True)
class ServoSetup:
    """The EEPROM items that decide where one servo can go: Operating Mode (11), Homing
    Offset (20) [ticks] and Min/Max Position Limit (52, 48) [ticks], as read from it."""

    mode: int
    homing_offset: int = 0
    min_position: int = POSITION_LIMIT_RANGE[0]
    max_position: int = POSITION_LIMIT_RANGE[1]

    @property
    def offset_in_force(self) -> int:
        """The Homing Offset the servo applies: Position Control Mode ignores one outside
        -1024 .. 1024 (e-Manual, Homing Offset (20))."""
        return effective_homing_offset(self.mode, self.homing_offset)

    def goal_bounds(self) -> tuple[int, int]:
        """Goal Positions [ticks] the servo accepts: Min .. Max Position Limit in Position
        Control Mode (data limit error outside), the register's range otherwise."""
        if self.mode == OperatingMode.POSITION:
            return self.min_position, self.max_position
        return GOAL_POSITION_RANGE

    def reachable(self) -> tuple[int, int] | None:
        """Present Positions [ticks] the servo can be held at in Position Control Mode:
        [max(0, H), min(4095, 4095 + H)] (goals within 0 .. 4095, positions after torque-on
        within H .. 4095 + H). None in multi-turn modes and in modes without position goals."""
        if self.mode != OperatingMode.POSITION:
            return None
        offset = self.offset_in_force
        low, high = POSITION_LIMIT_RANGE
        return max(low, offset), min(high, high + offset)


def effective_homing_offset(mode: int, homing_offset: int) -> int:
    """The Homing Offset [ticks] a servo in `mode` applies (0 where it ignores it)."""
    if mode == OperatingMode.POSITION and abs(homing_offset) > POSITION_MODE_HOMING_OFFSET_LIMIT:
        return 0
    return homing_offset


def single_turn(ticks: int, homing_offset: int) -> int:
    """The Present Position [ticks] of a shaft that reads `ticks` now, once its count is
    reset to one turn (torque on in Position Control Mode, power-on):
    ((ticks - H) mod 4096) + H, H the Homing Offset in force."""
    return (ticks - homing_offset) % TICKS_PER_REV + homing_offset


def turn_correction(present_ticks: int, cal: JointCalibration) -> int:
    """Whole turns k such that `present_ticks` + 4096 k lies nearest the middle of the
    joint's tick range: 0 when the servo reads on its calibrated turn. A multi-turn servo
    that comes up k turns away is put back by Homing Offset += 4096 k."""
    low, high = cal.tick_limits()
    return round(((low + high) / 2 - present_ticks) / TICKS_PER_REV)


def zero_offsets_within(cal: JointCalibration, window: tuple[int, int]) -> tuple[int, int] | None:
    """The zero offsets [ticks] (raw position at theta = 0) for which the joint's range
    lies inside `window`, or None if the range is wider than the window."""
    angles = (cal.min_angle_rad, cal.max_angle_rad)
    ends = sorted(cal.direction * round(a / RAD_PER_TICK) for a in angles)
    low, high = window[0] - ends[0], window[1] - ends[1]
    return (low, high) if low <= high else None


def check_joint(cal: JointCalibration, setup: ServoSetup, joint: int) -> None:
    """Refuse a joint range the servo cannot reach in its operating mode.

    cal: the joint's calibration; setup: the servo's mode, Homing Offset and limits;
    joint: the joint's number (1-based) for the message. Raises SeamError naming the
    servo, the joint, the range in rad and ticks, and the fix (see the module docstring).
    """
    low, high = cal.tick_limits()
    name = f"servo {cal.servo_id} (joint {joint})"
    span = f"joint range {cal.min_angle_rad:.3f} .. {cal.max_angle_rad:.3f} rad"
    window = setup.reachable()
    if window is None or window[0] <= low and high <= window[1]:
        return
    offset = setup.offset_in_force
    physical = (low - offset, high - offset)  # the range as one-turn encoder positions
    crosses = physical[0] < 0 or physical[1] > TICKS_PER_REV - 1
    where = (
        "crosses the encoder's seam at 4095/0, which a servo in Position Control Mode cannot "
        "turn through (a Homing Offset renames positions but does not move the seam)"
        if crosses
        else f"is outside what Homing Offset {offset} leaves reachable"
    )
    fixes = []
    if not crosses:  # within one turn: Homing Offset 0 leaves all of 0 .. 4095 reachable
        fixes.append(
            f"write Homing Offset (20) = 0 on servo {cal.servo_id} (torque off), then home again"
        )
    fixes.append(_remount_fix(cal, setup, window))
    fixes.append(
        f"or set Operating Mode (11) = {int(OperatingMode.EXTENDED_POSITION)} (Extended "
        "Position Control Mode, torque off) and home again: the servo then turns through "
        "the seam and the driver keeps the joint on its calibrated turn (docs/hardware.md)"
    )
    raise SeamError(
        f"{name}: {span} is Present Position {low} .. {high} ticks, but Position Control "
        f"Mode reaches only {window[0]} .. {window[1]}: the range {where}. Fix: " + "; ".join(fixes)
    )


def _remount_fix(cal: JointCalibration, setup: ServoSetup, window: tuple[int, int]) -> str:
    """'turn the upper link on its horn by A .. B ticks or C .. D ticks so that ...'."""
    zeros = zero_offsets_within(cal, window)
    low, high = cal.tick_limits()
    if zeros is None:
        return (
            f"narrow the joint range: its {high - low + 1} ticks do not fit in the "
            f"{window[1] - window[0] + 1} that Position Control Mode reaches"
        )
    now = single_turn(cal.zero_offset_ticks, setup.offset_in_force)
    # The shaft reads the same one turn up or down, so the link may turn either way: the
    # turns m that bring theta = 0 to read within `zeros`, nearest first on each side.
    spans = [
        (zeros[0] - now + k * TICKS_PER_REV, zeros[1] - now + k * TICKS_PER_REV) for k in (-1, 0, 1)
    ]
    down = max((s for s in spans if s[1] < 0), key=lambda s: s[1], default=None)
    up = min((s for s in spans if s[0] > 0), key=lambda s: s[0], default=None)
    turns = " or ".join(
        f"{near:+d} .. {far:+d} ticks ({_deg(near)} .. {_deg(far)} deg)"
        for near, far in _sides(down, up)
    )
    return (
        f"turn the upper link on its horn by {turns}, so that theta = 0 reads within "
        f"{zeros[0]} .. {zeros[1]} ticks (it reads {now}; mid-range is "
        f"{(zeros[0] + zeros[1]) // 2}), then home again"
    )


def _sides(down: tuple[int, int] | None, up: tuple[int, int] | None) -> list[tuple[int, int]]:
    """(nearest, farthest) turn of each side that has one."""
    sides = []
    if down is not None:
        sides.append((down[1], down[0]))
    if up is not None:
        sides.append((up[0], up[1]))
    return sides


def _deg(ticks: int) -> str:
    return f"{math.degrees(ticks * RAD_PER_TICK):+.1f}"
