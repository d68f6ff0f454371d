"""The wrist: a fourth servo on the legs' bus, turning the tool about the platform's z.

The loop sees the legs as before, through `WristBus`, a three-joint `ServoBus` in front of
the four-servo bus: each read is one sync read of all four servos, whose wrist column it
keeps (`WristReading`); each leg goal goes out in one sync write with the wrist's goal
appended (`WristBus.phi_rad`). So the operator commands that hold the legs (torque on,
e-stop) hold the wrist with them, and nothing else in the loop changes shape.

The wrist's goal phi [rad] (``LoopState.phi_goal_rad``) comes from a setpoint's
``phi_rad`` or from `turn_to`; the gate checks it against the wrist's limits (refused:
never written) and the tick turns the wrist towards it at most ``wrist.max_speed_rad_s``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from app.config import XM430_CURRENT_LIMIT_A
from app.control.commands import require_motion
from app.control.loop_state import LoopState
from app.control.state import WristReading
from hardware.bus import BusStats, JointState, OperatingMode, PositionGains, ServoBus, ServoInfo

N_LEGS = 3


class WristBus:
    """A bus of three legs and a wrist, shown to the loop as the legs' `ServoBus`.

    phi_rad: the wrist goal [rad] sent with every leg goal (None: the wrist holds where
    it was last read; the first write then keeps that); torque off forgets it, so torque
    on holds the wrist where it is, like the legs. reading: the wrist at the last read.
    Owned by the control thread, like the bus it wraps.
    """

    def __init__(self, bus: ServoBus, servo_id: int) -> None:
        self.bus = bus
        self.wrist_gains = PositionGains()
        self.wrist_gains_read: PositionGains | None = None  # as the wrist's registers said
        self.wrist_goal_current_a: float | None = None  # [A]; read when first needed
        self.servo_id = servo_id
        self.phi_rad: float | None = None
        self.reading: WristReading | None = None

    # -- the legs' ServoBus ----------------------------------------------------------------
    def connect(self) -> None:
        self.bus.connect()

    def disconnect(self) -> None:
        self.bus.disconnect()

    def scan(self, ids: Sequence[int] | None = None) -> list[ServoInfo]:
        return self.bus.scan(ids)

    def torque(self, enabled: bool) -> None:
        self.bus.torque(enabled)
        if not enabled:
            self.phi_rad = None

    def set_operating_mode(self, mode: OperatingMode) -> None:
        self.bus.set_operating_mode(mode)

    def set_goal_current(self, currents_a: Sequence[float]) -> None:
        """The legs' Goal Current [A], shape (3,); the wrist keeps its own
        (`wrist_goal_current_a`: as its servo held it when first asked, the full XM430
        Current Limit on a bus that cannot say). Raises ValueError (not three legs), and
        what the bus's set_goal_current raises."""
        if len(currents_a) != N_LEGS:
            raise ValueError(f"{len(currents_a)} leg goal currents for {N_LEGS} legs")
        if self.wrist_goal_current_a is None:
            read = getattr(self.bus, "read_goal_current", None)
            held = read()[N_LEGS] if read is not None else None
            self.wrist_goal_current_a = XM430_CURRENT_LIMIT_A if held is None else float(held)
        self.bus.set_goal_current([*currents_a, self.wrist_goal_current_a])

    def write_goal(self, positions_rad: Sequence[float]) -> None:
        """The legs' goals [rad], shape (3,), and the wrist's `phi_rad`, in one sync write.

        Raises ValueError (not three legs), RuntimeError (no goal for the wrist: nothing
        set and nothing read yet), and what the bus's write_goal raises.
        """
        if len(positions_rad) != N_LEGS:
            raise ValueError(f"{len(positions_rad)} leg goals for {N_LEGS} legs")
        if self.phi_rad is None:
            if self.reading is None:
                raise RuntimeError("no wrist goal and no wrist state read yet")
            self.phi_rad = self.reading.position_rad
        self.bus.write_goal([*positions_rad, self.phi_rad])

    def read_state(self) -> JointState:
        """One read of the four servos; the legs' part (arrays of shape (3,)). The wrist's
        part is kept in `reading`."""
        state = self.bus.read_state()
        k = N_LEGS
        self.reading = WristReading(
            float(state.position_rad[k]),
            float(state.velocity_rad_s[k]),
            float(state.current_a[k]),
            float(state.temperature_c[k]),
            tuple(state.hardware_errors[k]),
            None if state.torque_enabled is None else bool(state.torque_enabled[k]),
            float(state.voltage_v[k]),
            float(state.pwm[k]),
        )
        return state.joints(k)

    def set_profile(self, velocity_rad_s: float, acceleration_rad_s2: float) -> None:
        self.bus.set_profile(velocity_rad_s, acceleration_rad_s2)

    def set_gains(self, gains: PositionGains | Sequence[PositionGains]) -> None:
        """One set for every servo (the wrist's too), or one per leg: the wrist then keeps
        the gains it was last given (the factory's until then)."""
        if isinstance(gains, PositionGains):
            self.wrist_gains = gains
            self.bus.set_gains(gains)
        else:
            self.bus.set_gains([*gains, self.wrist_gains])

    def read_gains(self) -> list[PositionGains]:
        """The legs' gains (the wrist's is the last of the bus's: kept in
        `wrist_gains_read`)."""
        *legs, self.wrist_gains_read = self.bus.read_gains()
        return legs

    def reboot(self, ids: Sequence[int] | None = None) -> None:
        self.bus.reboot(ids)
        self.phi_rad = None  # a reboot leaves torque off

    @property
    def stats(self) -> BusStats:
        return self.bus.stats

    # -- the wrist ---------------------------------------------------------------------
    @property
    def faulted(self) -> bool:
        """The wrist's servo reported a hardware error at the last read."""
        return self.reading is not None and bool(self.reading.hardware_errors)

    @property
    def hardware_errors(self) -> tuple[str, ...]:
        """The names of the wrist servo's latched hardware errors at the last read."""
        return self.reading.hardware_errors if self.reading is not None else ()


def turn_to(state: LoopState, phi_rad: float) -> float:
    """Command the wrist to ``phi_rad`` [rad] (checked by the gate already); the tick turns
    it there at the wrist's speed limit. Raises MotionRefused when the robot may not move
    (e-stop, fault, torque off)."""
    require_motion(state)
    state.phi_goal_rad = state.phi_rad = float(phi_rad)  # the tip's goals follow the turn
    return state.phi_goal_rad


def next_phi(
    state: LoopState, wrist: WristBus, max_step_rad: float, goal_rad: float | None = None
) -> float | None:
    """The wrist goal to write this tick [rad]: towards ``goal_rad`` (None:
    ``state.phi_goal_rad``) by at most ``max_step_rad`` from the last one written (or from
    where it is); None when nothing is known yet (no goal written, nothing read)."""
    current = wrist.phi_rad
    if current is None:
        current = wrist.reading.position_rad if wrist.reading is not None else None
    goal = state.phi_goal_rad if goal_rad is None else goal_rad
    if current is None or goal is None:
        return current
    if abs(goal - current) <= max_step_rad:
        return goal  # exactly: the tick then sees the wrist arrived and stops writing
    return current + float(np.clip(goal - current, -max_step_rad, max_step_rad))
