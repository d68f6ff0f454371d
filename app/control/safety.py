"""Fault detection of the loop: bus misses, servo hardware errors, stale feedback,
following error.

Each detector only reports; the controller decides (stop, hold, fault). Following error
trips as in LinuxCNC: |commanded - measured| above a limit for longer than a time. It is
only checked on fresh feedback: a simulator that did not step hands back the state it
handed out before, and comparing a moving command with that frozen reading would call a
stale bus a lagging joint (a run once faulted "joint 3 lags 66.8 deg" after its simulator
had been starved for 0.5 s). Stale feedback trips on its own, naming itself.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.control.state import Fault
from hardware.bus import JointState


@dataclass
class MissCounter:
    """Consecutive failed bus transactions; faults at ``limit``."""

    limit: int
    consecutive: int = 0
    total: int = 0

    def miss(self) -> bool:
        """Count one miss; True when the limit is reached."""
        self.consecutive += 1
        self.total += 1
        return self.consecutive >= self.limit

    def ok(self) -> None:
        self.consecutive = 0


@dataclass
class FollowingError:
    """Trips when any joint lags its command by more than ``limit_rad`` for ``time_s``."""

    limit_rad: float
    time_s: float
    _over_since: float | None = None

    def check(self, now_s: float, commanded: np.ndarray, measured: np.ndarray) -> Fault | None:
        error = np.abs(commanded - measured)
        if not np.all(np.isfinite(error)) or error.max() <= self.limit_rad:
            self._over_since = None
            return None
        if self._over_since is None:
            self._over_since = now_s
        if now_s - self._over_since < self.time_s:
            return None
        joint = int(np.argmax(error))
        return Fault(
            "following",
            f"joint {joint + 1} lags its command by {np.degrees(error[joint]):.1f} deg "
            f"for {now_s - self._over_since:.2f} s (limit {np.degrees(self.limit_rad):.1f} deg)",
            time_s=now_s,
            kind="following",
        )

    def reset(self) -> None:
        self._over_since = None


STALE_MOTION_RAD = 0.01  # ~6.5 encoder ticks: a working servo commanded this far shows it


@dataclass
class FeedbackFreshness:
    """Whether each read brought news, and for how long the feedback has not.

    A state is stale when it is one the loop has seen before:

    - a simulated robot's state carries its simulated time (``JointState.sim_time_s``): a
      read whose simulated time did not advance since the previous read is stale, for sure
      (``certain``);
    - a real bus's read is a fresh transaction, but a reading identical to the previous one
      (position, velocity and current) while the command has moved more than
      ``STALE_MOTION_RAD`` since the reading last changed is reported as stale too: either
      the feedback is not news or the arm is blocked; a blocked arm is the following
      error's to fault, so this kind only informs (the run's health), never trips.

    ``age_s`` is the loop time since the last fresh reading [s] (0 on a fresh one).
    :meth:`fault` trips when a certain staleness has lasted longer than ``limit_s``.
    """

    limit_s: float
    stale: bool = False
    certain: bool = False
    age_s: float = 0.0
    command_moved_rad: float = 0.0  # how far the command moved since the last fresh state
    _previous: JointState | None = None
    _fresh_at_s: float | None = None
    _command_at_fresh: np.ndarray | None = None

    def update(self, now_s: float, joints: JointState, commanded: np.ndarray | None) -> bool:
        """One successful read at loop time ``now_s`` [s], with the command then in force
        (joint angles [rad], (3,), or None); returns whether the reading is stale."""
        previous, self._previous = self._previous, joints
        certain = joints.sim_time_s is not None
        if previous is None:
            stale = False
        elif joints.sim_time_s is not None and previous.sim_time_s is not None:
            stale = not joints.sim_time_s > previous.sim_time_s
        elif not self._same(joints, previous):
            stale = False
        else:  # the same reading: stale once the command has moved away from it
            moved = (
                commanded is not None
                and self._command_at_fresh is not None
                and float(np.max(np.abs(commanded - self._command_at_fresh))) > STALE_MOTION_RAD
            )
            stale = moved
            if not moved:  # an unchanged reading of an arm not asked to move is news enough
                self._fresh_at_s = now_s
                if self._command_at_fresh is None and commanded is not None:
                    self._command_at_fresh = np.array(commanded)
                return self._set(False, certain, now_s)
        if not stale:
            self._fresh_at_s = now_s
            self._command_at_fresh = None if commanded is None else np.array(commanded)
        self.command_moved_rad = (
            float(np.max(np.abs(commanded - self._command_at_fresh)))
            if stale and commanded is not None and self._command_at_fresh is not None
            else 0.0
        )
        return self._set(stale, certain, now_s)

    @staticmethod
    def _same(a: JointState, b: JointState) -> bool:
        return (
            np.array_equal(a.position_rad, b.position_rad)
            and np.array_equal(a.velocity_rad_s, b.velocity_rad_s)
            and np.array_equal(a.current_a, b.current_a)
        )

    def _set(self, stale: bool, certain: bool, now_s: float) -> bool:
        self.stale, self.certain = stale, stale and certain
        fresh_at = now_s if self._fresh_at_s is None else self._fresh_at_s
        self.age_s = now_s - fresh_at if stale else 0.0
        return stale

    def fault(self, now_s: float) -> Fault | None:
        """A fault once the simulator's time has stood still longer than ``limit_s`` while
        the command moved on (more than ``STALE_MOTION_RAD`` since the last fresh state). A
        frozen simulator holding a still arm is a frozen world, not a danger: that only
        marks the run's health (a loaded machine must not fault a robot at rest)."""
        if not (self.stale and self.certain and self.age_s > self.limit_s):
            return None
        if self.command_moved_rad <= STALE_MOTION_RAD:
            return None
        return Fault(
            "bus",
            f"stale feedback: the simulator's time did not advance for {self.age_s:.2f} s "
            f"(limit {self.limit_s:.2f} s); its state is old, not a lagging joint",
            time_s=now_s,
            kind="stale feedback",
        )

    def reset(self) -> None:
        self._previous, self._fresh_at_s, self._command_at_fresh = None, None, None
        self.stale, self.certain, self.age_s = False, False, 0.0
        self.command_moved_rad = 0.0


def servo_faults(
    servo_ids: tuple[int, ...], errors: tuple[tuple[str, ...], ...], now_s: float
) -> list[Fault]:
    """One Fault per servo that reports hardware error bits, naming them."""
    return [
        Fault("servo", f"servo {sid}: hardware error {', '.join(names)}", sid, now_s, "hardware")
        for sid, names in zip(servo_ids, errors, strict=True)
        if names
    ]
