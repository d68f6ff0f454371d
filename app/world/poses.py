"""Drone pose samples and the tracker that vets them for the control loop.

Every source (simulated drone, motion capture over WebSocket/UDP, MAVLink) pushes samples
here. The tracker rejects non-finite values and non-unit quaternions, drops out-of-order
and duplicate samples by their timestamp, estimates velocity when the source gives none,
and tells the loop how fresh the latest pose is: ok, stale (freeze the goal, warn) or
lost (fault).
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from kinematics import Pose, PoseError
from kinematics.pose import unit_quaternion

# the pose inputs a sample can come from (GET /api/mav/pose ``source``): the API's POST and
# WebSocket, the UDP and MAVLink listeners, and the simulated drone's feed (drone_feed.py)
SOURCES = ("http", "websocket", "udp", "mavlink", "simulated")


@dataclass(frozen=True)
class PoseSample:
    """Drone body pose in the world at source time ``t_s`` [s].

    position_m (3,) [m]; quaternion (4,) (w, x, y, z) body to world; velocity_m_s (3,)
    [m/s] and angular_velocity_rad_s (3,) [rad/s, body frame] when the source knows them.
    received_s: time.monotonic() at arrival (for staleness). source: which input sent it
    (one of ``SOURCES``: http, websocket, udp, mavlink, simulated).
    """

    t_s: float
    position_m: np.ndarray
    quaternion: np.ndarray
    velocity_m_s: np.ndarray | None = None
    angular_velocity_rad_s: np.ndarray | None = None
    received_s: float = 0.0
    source: str = "http"

    @property
    def pose(self) -> Pose:
        return Pose(self.position_m, self.quaternion)


def make_sample(
    t_s: Any,
    position_m: Any,
    quaternion: Any,
    velocity_m_s: Any = None,
    angular_velocity_rad_s: Any = None,
    received_s: float | None = None,
    source: str = "http",
) -> PoseSample:
    """A validated sample; PoseError names the bad field (``source`` one of ``SOURCES``)."""
    if source not in SOURCES:
        raise PoseError(f"source: {source!r} is not one of {', '.join(SOURCES)}")
    if not isinstance(t_s, (int, float)) or not math.isfinite(t_s):
        raise PoseError(f"t: must be a finite time in seconds, got {t_s!r}")
    position = Pose.from_arrays(position_m).position
    if position.shape != (3,):
        raise PoseError(f"position: expected 3 numbers, got shape {position.shape}")
    extras = []
    for name, value in (("velocity", velocity_m_s), ("angular_velocity", angular_velocity_rad_s)):
        vector = None if value is None else np.asarray(value, dtype=np.float64)
        if vector is not None and (vector.shape != (3,) or not np.isfinite(vector).all()):
            raise PoseError(f"{name}: expected 3 finite numbers, got {value!r}")
        extras.append(vector)
    return PoseSample(
        float(t_s),
        position,
        unit_quaternion(quaternion),
        *extras,
        received_s=time.monotonic() if received_s is None else received_s,
        source=source,
    )


class PoseTracker:
    """Latest vetted pose of one source; thread-safe (sources push from their threads)."""

    def __init__(self, stale_after_s: float, lost_after_s: float, max_jump_m: float) -> None:
        self.stale_after_s, self.lost_after_s, self.max_jump_m = (
            stale_after_s,
            lost_after_s,
            max_jump_m,
        )
        self._lock = threading.Lock()
        self._latest: PoseSample | None = None
        self._previous: PoseSample | None = None
        self.accepted = 0
        self.dropped = 0
        self.jumps = 0
        self.restarts = 0
        self.refused_frames: dict[str, int] = {}
        self._rate_hz = 0.0

    def push(self, sample: PoseSample) -> bool:
        """Keep ``sample`` if newer than the latest; False when dropped (old, duplicate, jump).

        A sample arriving more than ``lost_after_s`` after the latest kept one starts the
        stream afresh (``restarts``): its time and position are the new baseline, so a
        restarted source (its clock from 0 again) or one back after an occlusion (or after
        a bad first sample) is not refused for ever as out of order or jumping."""
        with self._lock:
            latest = self._latest
            if latest is not None and sample.received_s - latest.received_s > self.lost_after_s:
                self.restarts += 1
                self._previous, self._latest, self._rate_hz = None, sample, 0.0
                self.accepted += 1
                return True
            if latest is not None and sample.t_s <= latest.t_s:
                self.dropped += 1
                return False
            if latest is not None:
                jump = float(np.linalg.norm(sample.position_m - latest.position_m))
                if jump > self.max_jump_m:
                    self.jumps += 1
                    self.dropped += 1
                    return False
                gap = sample.t_s - latest.t_s
                self._rate_hz = 0.9 * self._rate_hz + 0.1 / gap if self._rate_hz else 1.0 / gap
            self._previous, self._latest = latest, sample
            self.accepted += 1
            return True

    def refuse(self, key: str) -> None:
        """Count a message its source refused for a frame it does not take, under ``key``
        (e.g. "child_frame_id MAV_FRAME_LOCAL_ENU"): ``refused_frames`` in the status."""
        with self._lock:
            self.refused_frames[key] = self.refused_frames.get(key, 0) + 1

    def latest(self) -> tuple[PoseSample | None, np.ndarray]:
        """(latest sample, its velocity [m/s]: supplied, else from the last two samples)."""
        with self._lock:
            latest, previous = self._latest, self._previous
        if latest is None:
            return None, np.zeros(3)
        if latest.velocity_m_s is not None:
            return latest, latest.velocity_m_s
        if previous is None:
            return latest, np.zeros(3)
        return latest, (latest.position_m - previous.position_m) / (latest.t_s - previous.t_s)

    def health(self, now_s: float | None = None) -> tuple[str, float]:
        """('ok' | 'stale' | 'lost' | 'none', age of the latest sample [s])."""
        now = time.monotonic() if now_s is None else now_s
        with self._lock:
            latest = self._latest
        if latest is None:
            return "none", math.inf
        age = now - latest.received_s
        if age > self.lost_after_s:
            return "lost", age
        return ("stale" if age > self.stale_after_s else "ok"), age

    def status(self) -> dict[str, Any]:
        """The stream's health (state, age [s], rate [Hz], counters) and its latest sample:
        ``source`` (the input it came from), ``position_m`` [m] and ``quaternion`` (w, x,
        y, z, body to world); the three None before any sample."""
        state, age = self.health()
        with self._lock:
            latest = self._latest
        return {
            "state": state,
            "age_s": None if math.isinf(age) else age,
            "source": None if latest is None else latest.source,
            "position_m": None if latest is None else latest.position_m.tolist(),
            "quaternion": None if latest is None else latest.quaternion.tolist(),
            "rate_hz": self._rate_hz,
            "accepted": self.accepted,
            "dropped": self.dropped,
            "jumps": self.jumps,
            "restarts": self.restarts,
            "refused_frames": dict(self.refused_frames),
        }
