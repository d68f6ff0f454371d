"""The drone's motion felt by the arm: the twin simulates in the (moving) base frame.

In a frame that accelerates by a (its origin, world frame) and turns at w with w' (base
frame), a body of mass m at r moving at v (both in the base frame) feels, besides gravity,

    F = -m (R^T a + w' x r + w x (w x r) + 2 w x v)

The first term joins gravity as the effective gravity R^T (g - a), exact for every body.
The rest (Euler, centrifugal, Coriolis) is applied as a force at each body's centre of
mass, which is exact for the resultant force (all three are linear in r and v) but leaves
out the moments they make about the body's own centre of mass: second order for the
slender links of a Delta. `BaseMotion` itself is hardware/base_motion.py (no MuJoCo there).
"""

from __future__ import annotations

import mujoco
import numpy as np

from hardware.base_motion import BaseMotion


def apply_frame_forces(
    model: mujoco.MjModel, data: mujoco.MjData, bodies: np.ndarray, motion: BaseMotion
) -> None:
    """Write the Euler, centrifugal and Coriolis forces [N] of `motion` on `bodies` (an
    int array) into data.xfrc_applied (at each centre of mass), from the current positions
    and speeds. All bodies at once: per body it cost 0.8 s per simulated second, more than
    the twin's real-time budget; vectorized it is a few per cent of it."""
    w = np.asarray(motion.angular_velocity_rad_s, dtype=float)
    w_dot = np.asarray(motion.angular_acceleration_rad_s2, dtype=float)
    r = data.xipos[bodies]  # centres of mass (world = base frame here)
    # cvel is (angular, linear) at the subtree centre of mass of each body's root
    spin, linear = data.cvel[bodies, :3], data.cvel[bodies, 3:]
    velocity = linear + _cross(spin, r - data.subtree_com[model.body_rootid[bodies]])
    accel = _cross(w_dot, r) + _cross(w, _cross(w, r)) + 2.0 * _cross(w, velocity)
    data.xfrc_applied[bodies, :3] = -model.body_mass[bodies, None] * accel


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b for (n, 3) rows (a may be one (3,) vector): np.cross's axis handling costs
    more than the arithmetic at a handful of bodies."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack((a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0), axis=-1)
