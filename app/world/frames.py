"""MAVLink frames to the project's: NED/FRD (PX4, ArduPilot) to ENU-style world z-up, FLU body.

The world frame here is z up (thesis: the Delta hangs below the drone, platform at
z < 0). MAVLink's local frame is North-East-Down and its body frame Forward-Right-Down;
we use x = East, y = North, z = Up in the world and Forward-Left-Up on the body.
"""

from __future__ import annotations

import numpy as np

from kinematics.pose import quaternion_multiply

S = float(np.sqrt(0.5))
# rotation taking NED coordinates to ENU: swap x and y, negate z (180 deg about (1, 1, 0)/sqrt 2)
Q_ENU_FROM_NED = np.array([0.0, S, S, 0.0])
# rotation taking FLU body coordinates to FRD: 180 deg about x
Q_FRD_FROM_FLU = np.array([0.0, 1.0, 0.0, 0.0])


def ned_to_enu(vector: np.ndarray) -> np.ndarray:
    """A NED vector (*, 3) in ENU coordinates."""
    v = np.asarray(vector, dtype=np.float64)
    return np.stack([v[..., 1], v[..., 0], -v[..., 2]], axis=-1)


def frd_to_flu(vector: np.ndarray) -> np.ndarray:
    """An FRD body vector (*, 3) (e.g. an angular velocity) in FLU coordinates."""
    v = np.asarray(vector, dtype=np.float64)
    return np.stack([v[..., 0], -v[..., 1], -v[..., 2]], axis=-1)


def attitude_ned_frd_to_enu_flu(q_ned_frd: np.ndarray) -> np.ndarray:
    """Body-to-world quaternion (w, x, y, z): FRD->NED in, FLU->ENU out."""
    q = quaternion_multiply(Q_ENU_FROM_NED, quaternion_multiply(q_ned_frd, Q_FRD_FROM_FLU))
    return q if q[0] >= 0 else -q
