"""The legs' servos' operating mode and Goal Current: position, or current-based position.

In Current-based Position Control Mode (Dynamixel Operating Mode 5) the servo follows its
position goal as in Position Control Mode but its firmware bounds the motor current by
Goal Current (102), so each joint's torque never exceeds Kt * Goal Current: pressed on a
surface or caught on an obstacle, the joint gives way instead of fighting it. The mode is
an EEPROM item (written only with torque off); Goal Current is a RAM item, and a mode
change resets it to the Current Limit, so it is written after the mode.

The config (``[hardware] operating_mode``, ``goal_current_a``) is applied when the loop
starts (`Controller.start`), and `Controller.set_servo_current` changes both while torque
is off. The gate checks every setpoint the same in both modes.
"""

from __future__ import annotations

from collections.abc import Sequence

from app.config import XM430_CURRENT_LIMIT_A
from app.control.errors import MotionRefused
from app.control.loop_state import LoopState
from hardware.bus import OperatingMode, ServoBus

MODES: dict[str, OperatingMode] = {
    "position": OperatingMode.POSITION,
    "current_based_position": OperatingMode.CURRENT_BASED_POSITION,
}
#: What the servos hold when nothing was written: Position Control Mode (the factory's)
#: and Goal Current at the Current Limit (the firmware's power-on value).
DEFAULT_MODE = "position"
DEFAULT_GOAL_CURRENT_A = (XM430_CURRENT_LIMIT_A,) * 3


class TorqueOnError(MotionRefused):
    """The operating mode changes only with torque off (an EEPROM item): a MotionRefused,
    so the API answers 409 and the link carries it as a refusal."""


def check(mode: str, currents_a: Sequence[float]) -> tuple[float, float, float]:
    """`currents_a` [A] as three floats after checking `mode` and them.

    Raises ValueError naming the field: ``operating_mode`` not one of MODES;
    ``goal_current_a`` not three values, or one not > 0 and <= the XM430-W210's Current
    Limit (3.209 A).
    """
    if mode not in MODES:
        raise ValueError(f"operating_mode {mode!r}: must be one of {sorted(MODES)}")
    values = [float(c) for c in currents_a]
    if len(values) != 3:
        raise ValueError(f"goal_current_a: {len(values)} values, expected one per leg (3)")
    for joint, value in enumerate(values, start=1):
        if not 0 < value <= XM430_CURRENT_LIMIT_A:  # NaN fails too
            raise ValueError(
                f"goal_current_a of joint {joint}: {value} A must be > 0 and <= "
                f"{XM430_CURRENT_LIMIT_A:.4g} A (the XM430-W210's Current Limit)"
            )
    return values[0], values[1], values[2]


def apply(state: LoopState, servos: ServoBus, mode: str, currents_a: Sequence[float]) -> None:
    """Write `mode` (Operating Mode, torque must be off) and then the legs' Goal Current
    [A] (3,) to `servos`, and record both in `state` (they show in the snapshot).

    Raises ValueError (`check`); TorqueOnError while the loop has torque on (nothing
    written); what the bus raises (BusError, ValueError for a value above a servo's own
    Current Limit): the state then keeps what was last written whole.
    """
    currents = check(mode, currents_a)
    if state.torque:
        raise TorqueOnError(
            "the operating mode changes only with torque off (an EEPROM item): turn torque "
            "off first"
        )
    servos.set_operating_mode(MODES[mode])
    state.servo_mode = mode
    state.goal_current_a = DEFAULT_GOAL_CURRENT_A  # the firmware resets it with the mode
    servos.set_goal_current(list(currents))
    state.goal_current_a = currents
