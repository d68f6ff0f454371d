"""Fault detection of the loop: bus misses, servo hardware errors, following error.

Each detector only reports; the controller decides (stop, hold, fault). Following error
trips as in LinuxCNC: |commanded - measured| above a limit for longer than a time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.control.state import Fault


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


def servo_faults(
    servo_ids: tuple[int, ...], errors: tuple[tuple[str, ...], ...], now_s: float
) -> list[Fault]:
    """One Fault per servo that reports hardware error bits, naming them."""
    return [
        Fault("servo", f"servo {sid}: hardware error {', '.join(names)}", sid, now_s, "hardware")
        for sid, names in zip(servo_ids, errors, strict=True)
        if names
    ]
