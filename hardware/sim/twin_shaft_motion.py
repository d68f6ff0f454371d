"""The twin as the emulator's MotionModel: control tables on the pty drive the MuJoCo arm.

hardware.emulator.ServoEmulator steps its model by the wall time between packets with one
MotionCommand per servo (shaft angles [rad], raw ticks * 2 pi / 4096); this adapter hands
those commands to the twin's servo models and returns the shafts' motion, so a gain or a
profile written over the real SDK changes the simulated robot.
"""

from __future__ import annotations

from collections.abc import Sequence

from hardware.shaft_motion import MAX_CATCH_UP_S, MotionCommand, MotionState
from hardware.sim.twin import DeltaTwin, TwinConfig
from hardware.sim.xm430 import ServoOutput


class TwinMotionModel:
    """MotionModel of the simulated Delta's servos: three legs, and a wrist fourth if the
    config has one (emulator order = leg order, the wrist last)."""

    def __init__(self, config: TwinConfig | None = None) -> None:
        self.twin = DeltaTwin(config)

    def reset(self, positions_rad: Sequence[float]) -> None:
        """Place the arm at rest with the shafts at `positions_rad` [rad] (through the
        calibrations; shafts whose joint angles have no FK leave the assembled home)."""
        joints = self.twin.joints_of_shafts(positions_rad)
        try:
            self.twin.reset(joints)
        except ValueError:
            self.twin.reset()

    def step(self, dt_s: float, commands: Sequence[MotionCommand]) -> Sequence[MotionState]:
        """Advance `dt_s` [s] (capped like the emulator's own model) under `commands`."""
        self.twin.set_commands(commands)
        self.twin.advance(min(max(0.0, dt_s), MAX_CATCH_UP_S))
        shafts, speeds = self.twin.shaft_rad, self.twin.shaft_rad_s
        outs = self.twin.outputs
        return [
            MotionState(float(shafts[k]), float(speeds[k]), outs[k].current_a)
            for k in range(self.twin.n_servos)
        ]

    def reboot(self, index: int) -> None:
        """Clear servo `index`'s latched error (for the emulator's Reboot instruction)."""
        self.twin.servos[index].reboot()

    @property
    def outputs(self) -> list[ServoOutput]:
        """Temperature and Hardware Error Status per servo, for the emulator's tables."""
        return self.twin.outputs
