"""A simulated hovering drone: band-limited drift, attitude wobble and gusts, seeded.

The true pose is a deterministic function of time (sums of sinusoids with random phases
up to ``bandwidth_hz``, plus smooth gust pulses), so a run can be repeated exactly. The
measured pose is the true one ``latency_s`` late, sampled at ``rate_hz``: what a motion
capture system behind a filter delivers. Defaults are a realistic hover: a few cm of drift
and a few degrees of tilt (the thesis's Table 6.3 errors came from such drift).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from kinematics import Pose


@dataclass(frozen=True)
class DroneSimParams:
    """drift_m: RMS position drift per axis [m]; tilt_deg: RMS roll/pitch [deg]; yaw_deg:
    RMS yaw [deg]; bandwidth_hz: highest drift frequency; gust_m / gust_every_s: size and
    mean spacing of gust pulses; hover_m: mean position [m]; rate_hz, latency_s: the
    measurement; seed: repeatability."""

    drift_m: float = 0.02
    tilt_deg: float = 2.0
    yaw_deg: float = 2.0
    bandwidth_hz: float = 0.8
    gust_m: float = 0.015
    gust_every_s: float = 4.0
    hover_m: tuple[float, float, float] = (0.0, 0.0, 1.5)
    rate_hz: float = 100.0
    latency_s: float = 0.02
    seed: int = 0


@dataclass
class SimulatedDrone:
    params: DroneSimParams = field(default_factory=DroneSimParams)

    def __post_init__(self) -> None:
        rng = np.random.default_rng(self.params.seed)
        count = 12
        self._freq = rng.uniform(0.05, self.params.bandwidth_hz, (6, count))
        self._phase = rng.uniform(0, 2 * math.pi, (6, count))
        self._amp = rng.uniform(0.5, 1.0, (6, count))
        self._amp *= math.sqrt(2.0) / np.sqrt(np.sum(self._amp**2, axis=1, keepdims=True))
        self._gust_t = np.cumsum(rng.exponential(self.params.gust_every_s, 64))
        self._gust_dir = rng.normal(size=(64, 3))
        self._gust_dir /= np.linalg.norm(self._gust_dir, axis=1, keepdims=True)

    def _signals(self, t: float, order: int) -> np.ndarray:
        """Six unit-RMS band-limited signals (x, y, z, roll, pitch, yaw) or their rates."""
        w = 2 * math.pi * self._freq
        return np.sum(
            self._amp * w**order * np.sin(w * t + self._phase + order * math.pi / 2), axis=1
        )

    def _gust(self, t: float, order: int) -> np.ndarray:
        width = 0.4  # a pulse of ~1 s: dt = t - t_k, g = exp(-dt^2 / (2 w^2))
        dt = t - self._gust_t
        bump = np.exp(-(dt**2) / (2 * width**2))
        scale = bump if order == 0 else -dt / width**2 * bump
        return self.params.gust_m * (scale[:, None] * self._gust_dir).sum(axis=0)

    def true_state(self, t: float) -> tuple[Pose, np.ndarray]:
        """(true pose at time t [s], true velocity [m/s])."""
        p = self.params
        s, rate = self._signals(t, 0), self._signals(t, 1)
        position = np.asarray(p.hover_m) + p.drift_m * s[:3] + self._gust(t, 0)
        velocity = p.drift_m * rate[:3] + self._gust(t, 1)
        roll, pitch = np.radians(p.tilt_deg) * s[3:5]
        yaw = np.radians(p.yaw_deg) * s[5]
        return Pose(position, _rpy_quaternion(roll, pitch, yaw)), velocity

    def acceleration(self, t: float) -> np.ndarray:
        """True acceleration of the drone's centre [m/s^2] at time t [s]."""
        h = 1e-3  # the signals are smooth sums of sinusoids and Gaussians: differences suffice
        return (self.true_state(t + h)[1] - self.true_state(t - h)[1]) / (2 * h)

    def measured(self, t: float) -> tuple[float, Pose, np.ndarray]:
        """The newest measurement available at time t: (its stamp, pose, velocity)."""
        period = 1.0 / self.params.rate_hz
        stamp = math.floor((t - self.params.latency_s) / period) * period
        pose, velocity = self.true_state(stamp)
        return stamp, pose, velocity


def _rpy_quaternion(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """(w, x, y, z) of R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return np.array(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ]
    )
