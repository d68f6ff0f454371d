"""The jerk-limited rest-to-rest profile along one segment (exact stop at both ends).

The time-optimal 1-D motion from rest over a distance S with |v| <= V, |a| <= A and
|j| <= J (the 7-phase "S-curve"): jerk +J, constant A, jerk -J up to the cruise speed,
cruise, then the mirror image. The acceleration part lasts Ta with jerk phases of Tj:

- Tj = A / J and Ta = V / A + A / J when V J >= A^2 (A is reached), else
  Tj = sqrt(V / J), Ta = 2 Tj (peak acceleration J Tj < A);
- it covers V Ta / 2, so a segment shorter than V Ta never cruises: V drops to the
  speed where V Ta(V) = S, i.e. V^2 / A + V A / J = S, or 2 V^(3/2) / sqrt(J) = S.

Same durations as ruckig's 1-DOF rest-to-rest solution (tests/programs/test_profile.py
compares them); written out here so thousands of segments are timed and sampled in a few
NumPy operations instead of one ruckig call per sample.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Profile:
    """One segment's timing: distance [m], cruise speed [m/s], jerk [m/s^3], jerk phase
    Tj, acceleration part Ta, cruise Tv and total duration [s]."""

    distance: float
    speed: float
    jerk: float
    tj: float
    ta: float
    tv: float

    @property
    def duration(self) -> float:
        return 2.0 * self.ta + self.tv

    @property
    def peak_acceleration(self) -> float:
        return self.jerk * self.tj


def _accel_part(speed: float, accel: float, jerk: float) -> tuple[float, float]:
    if speed * jerk >= accel * accel:
        return accel / jerk, speed / accel + accel / jerk
    tj = math.sqrt(speed / jerk)
    return tj, 2.0 * tj


def rest_to_rest(distance: float, speed: float, accel: float, jerk: float) -> Profile:
    """The time-optimal profile over ``distance`` >= 0 [m] within the limits (all > 0).

    Raises:
        ValueError: a limit that is not finite and > 0.
    """
    for name, value in (("speed", speed), ("acceleration", accel), ("jerk", jerk)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} limit must be finite and > 0, got {value}")
    if distance <= 0:
        return Profile(0.0, 0.0, jerk, 0.0, 0.0, 0.0)
    tj, ta = _accel_part(speed, accel, jerk)
    if speed * ta > distance:  # no cruise: the highest speed the distance allows
        k = accel / jerk
        speed = 0.5 * accel * (-k + math.sqrt(k * k + 4.0 * distance / accel))
        if speed * jerk < accel * accel:
            speed = (distance * math.sqrt(jerk) / 2.0) ** (2.0 / 3.0)
        tj, ta = _accel_part(speed, accel, jerk)
    tv = max(distance / speed - ta, 0.0)
    return Profile(distance, speed, jerk, tj, ta, tv)


def _accel_phase(tau: np.ndarray, speed, jerk, tj, ta) -> tuple[np.ndarray, ...]:
    """s, v, a, j of the acceleration part at tau in [0, Ta] (arrays, per sample)."""
    peak = jerk * tj
    tc = ta - 2.0 * tj
    s1, v1 = jerk * tj**3 / 6.0, jerk * tj**2 / 2.0
    # phase 1: jerk +J
    s = jerk * tau**3 / 6.0
    v = jerk * tau**2 / 2.0
    a = jerk * tau
    j = np.broadcast_to(jerk, tau.shape).astype(np.float64)
    # phase 2: constant acceleration
    u = tau - tj
    middle = (tau >= tj) & (u <= tc)
    s = np.where(middle, s1 + v1 * u + peak * u**2 / 2.0, s)
    v = np.where(middle, v1 + peak * u, v)
    a = np.where(middle, peak, a)
    j = np.where(middle, 0.0, j)
    # phase 3: jerk -J, mirror of phase 1 about the end of the part
    left = ta - tau
    last = u > tc
    s = np.where(last, speed * ta / 2.0 - speed * left + jerk * left**3 / 6.0, s)
    v = np.where(last, speed - jerk * left**2 / 2.0, v)
    a = np.where(last, jerk * left, a)
    j = np.where(last, -jerk, j)
    return s, v, a, j


def evaluate(
    tau: np.ndarray,
    distance: np.ndarray,
    speed: np.ndarray,
    jerk: np.ndarray,
    tj: np.ndarray,
    ta: np.ndarray,
    tv: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(s, ds/dt, d2s/dt2, d3s/dt3) at local times ``tau`` (N,) [s], each profile's
    parameters given per sample (N,); tau is clamped to [0, duration]."""
    duration = 2.0 * ta + tv
    tau = np.clip(tau, 0.0, duration)
    decel = tau > ta + tv
    mirrored = np.where(decel, duration - tau, np.minimum(tau, ta))
    s, v, a, j = _accel_phase(mirrored, speed, jerk, tj, ta)
    cruise = (tau > ta) & ~decel
    s = np.where(cruise, speed * ta / 2.0 + speed * (tau - ta), s)
    v = np.where(cruise, speed, v)
    a = np.where(cruise, 0.0, a)
    j = np.where(cruise, 0.0, j)
    s = np.where(decel, distance - s, s)
    a = np.where(decel, -a, a)
    return s, v, a, j
