"""The drone's motion as the arm feels it: the base's attitude, acceleration and turning.

`SimulatedBus.set_base_motion` (hardware/bus.py) takes a `BaseMotion`; the MuJoCo twin turns
it into effective gravity and frame forces (hardware/sim/base_frame.py). NumPy only, so the
bus interface and the app can name it without loading MuJoCo.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

GRAVITY_M_S2 = 9.81


@dataclass(frozen=True)
class BaseMotion:
    """The base's attitude (quaternion w, x, y, z, body to world), the acceleration of its
    origin in the world [m/s^2], and its angular velocity [rad/s] and acceleration
    [rad/s^2] in the base frame.

    position_m: the base origin in the world [m], (3,), None when not known (then the
    world is the base frame: nothing moves a plate fixed in the world); velocity_m_s: that
    origin's velocity in the world [m/s], (3,). With a position the twin moves its
    world-fixed plates to base^-1 * plate_world (hardware.sim.surfaces.Plate.fixed_in),
    at the velocity that follows from velocity_m_s and angular_velocity_rad_s.

    Raises:
        ValueError: position_m or velocity_m_s not three finite numbers (naming it).
    """

    attitude_wxyz: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    acceleration_m_s2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    angular_velocity_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    angular_acceleration_rad_s2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    position_m: tuple[float, float, float] | None = None
    velocity_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        for name in ("position_m", "velocity_m_s"):
            value = getattr(self, name)
            if value is None and name == "position_m":
                continue
            try:
                triple = tuple(float(v) for v in value)
            except (TypeError, ValueError):
                raise ValueError(f"{name}: must be three numbers, got {value!r}") from None
            if len(triple) != 3 or not all(math.isfinite(v) for v in triple):
                raise ValueError(f"{name}: must be three finite numbers, got {list(triple)}")
            object.__setattr__(self, name, triple)

    @property
    def rotating(self) -> bool:
        """Whether the base turns (then per-body frame forces are needed every step)."""
        return any(self.angular_velocity_rad_s) or any(self.angular_acceleration_rad_s2)

    def effective_gravity(self) -> np.ndarray:
        """R^T (g - a) [m/s^2] in the base frame, shape (3,)."""
        g_world = np.array([0.0, 0.0, -GRAVITY_M_S2]) - np.asarray(self.acceleration_m_s2)
        return rotation(self.attitude_wxyz).T @ g_world


def rotation(quaternion_wxyz: Sequence[float]) -> np.ndarray:
    """Rotation matrix (3, 3) of a quaternion (w, x, y, z); normalized first."""
    w, x, y, z = np.asarray(quaternion_wxyz, dtype=float) / np.linalg.norm(quaternion_wxyz)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
