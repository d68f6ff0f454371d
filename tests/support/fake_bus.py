"""A fake servo bus for tests of the control layer without a thread, a simulator or a pty:
it records torque / write_goal / reboot calls and reads back an ideal servo (or a stuck one,
or one whose reads and writes fail; or, as a simulator, one that carries its simulated time
and can be paused, when its reads repeat the last state)."""

from __future__ import annotations

import time

import numpy as np

from app.config import load_settings
from hardware.bus import JointState
from hardware.errors import CommError

ROBOT = load_settings().robot.build()
HOME_M = np.array([0.0, 0.0, -0.22])
HOME_RAD = tuple(float(q) for q in ROBOT.ik(HOME_M).joints)  # inside every default limit
NO_ERRORS: tuple[tuple[str, ...], ...] = ((), (), ())


class FakeBus:
    """Records torque / write_goal / reboot; reads back an ideal servo (or a stuck one)."""

    def __init__(
        self, errors: tuple[tuple[str, ...], ...] = NO_ERRORS, sim_step_s: float | None = None
    ) -> None:
        self.calls: list[tuple] = []
        self.position = np.array(HOME_RAD)
        self.errors = errors
        self.fail_reads = self.fail_writes = self.stuck = False
        # as a simulator: each read steps simulated time by sim_step_s, unless paused
        self.sim_step_s, self.sim_time_s, self.paused = sim_step_s, 0.0, False
        self.read_delay_s = 0.0  # a slow read: starves the loop that waits for it
        self._last: JointState | None = None

    def torque(self, enabled: bool) -> None:
        self._fail_if(self.fail_writes, "write torque")
        self.calls.append(("torque", enabled))

    def write_goal(self, positions_rad) -> None:
        self._fail_if(self.fail_writes, "sync write goal")
        self.calls.append(("write_goal", tuple(float(q) for q in positions_rad)))
        if not self.stuck:
            self.position = np.array(positions_rad, dtype=np.float64)

    def reboot(self, ids=None) -> None:
        self.calls.append(("reboot", tuple(ids)))
        self.errors = NO_ERRORS

    def read_state(self) -> JointState:
        self._fail_if(self.fail_reads, "sync read state")
        if self.read_delay_s:
            time.sleep(self.read_delay_s)
        if self.paused and self._last is not None:
            return self._last  # a paused simulator: the state it handed out before
        if self.sim_step_s is not None:
            self.sim_time_s += self.sim_step_s
        n = len(self.position)  # three legs, or four with a wrist (set position and errors)
        self._last = JointState(
            position_rad=self.position.copy(),
            velocity_rad_s=np.zeros(n),
            current_a=np.zeros(n),
            voltage_v=np.full(n, 12.0),
            temperature_c=np.full(n, 30.0),
            pwm=np.zeros(n),
            moving=np.zeros(n, dtype=bool),
            hardware_errors=self.errors,
            stamp_s=time.monotonic(),
            sim_time_s=None if self.sim_step_s is None else self.sim_time_s,
        )
        return self._last

    @staticmethod
    def _fail_if(failing: bool, instruction: str) -> None:
        if failing:
            raise CommError((1, 2, 3), instruction, "no status packet (fake)")
