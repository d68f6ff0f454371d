"""Gravity compensation by a model-based offset: the servo goal shifted by the predicted sag.

A position-controlled XM430 with P only holds a joint like a torsion spring: at rest its
firmware drives PWM = (P / 128) e (e in encoder ticks, hardware/sim/xm430.py, the e-manual's
Position P Gain), the motor's current is that voltage over the winding resistance (no
back-EMF at rest), and its torque Kt times that current. So the joint's stiffness is

    k = (P / 128) * (4096 / 2 pi) * (V_supply / 885) * (Kt / R)    [N m / rad]

with Kt / R = stall torque / rated voltage (the datasheet's torque-speed line). The factory
P = 800 at 12 V gives k = 13.8 N m / rad. Under gravity the joint rests where the spring
holds the arm's weight: theta = goal - tau_g / k, tau_g the torque that holds the arm at
rest (kinematics.dynamics.inverse_dynamics_joints at zero speed and acceleration, thesis
eq. 3.113-3.125). Commanding goal + tau_g(goal) / k puts the arm back on the goal, to first
order (the sag is ~10 mrad, over which tau_g barely changes). Friction (the twin's 0.02 N m,
~1.5 mrad) and the encoder's tick (1.5 mrad) remain.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hardware.bus import PositionGains
from kinematics import RotaryDelta
from kinematics.dynamics import THESIS_MASS, MassModel, inverse_dynamics_joints

TICKS_PER_TURN = 4096
PWM_FULL_SCALE = 885  # PWM register units at 100 % (the e-manual's PWM Limit maximum)
# XM430-W210 at 12 V (ROBOTIS datasheet; the same constants as hardware/sim/xm430.py)
STALL_TORQUE_NM = 3.0
RATED_VOLTAGE_V = 12.0


def position_stiffness_nm_rad(
    p_gain: int = PositionGains().p,
    supply_voltage_v: float = RATED_VOLTAGE_V,
    stall_torque_nm: float = STALL_TORQUE_NM,
    rated_voltage_v: float = RATED_VOLTAGE_V,
) -> float:
    """Static stiffness [N m/rad] of the XM430's P-only position loop at rest.

    k = (P / 128) * (4096 / 2 pi) * (V_supply / 885) * (stall torque / rated voltage):
    PWM per rad of error, volts per PWM unit, and stall torque per volt (Kt / R at zero
    speed). Raises ValueError on a gain that is not positive.
    """
    if not p_gain > 0:
        raise ValueError(f"p_gain = {p_gain!r}: must be > 0 for a stiffness")
    pwm_per_rad = p_gain / 128.0 * TICKS_PER_TURN / (2.0 * math.pi)
    return pwm_per_rad * supply_voltage_v / PWM_FULL_SCALE * stall_torque_nm / rated_voltage_v


@dataclass(frozen=True)
class GravityOffset:
    """The goal offset that cancels each joint's sag under gravity.

    robot: the rotary Delta; mass: its mass model (payload included); stiffness_nm_rad:
    each joint's position-loop stiffness [N m/rad] (`position_stiffness_nm_rad`): one for
    all, or one per joint (3,); inf where the loop needs no offset (`loop_stiffness_nm_rad`).
    """

    robot: RotaryDelta
    mass: MassModel = THESIS_MASS
    stiffness_nm_rad: float | np.ndarray = position_stiffness_nm_rad()

    def __post_init__(self) -> None:
        k = np.asarray(self.stiffness_nm_rad, dtype=float)
        if k.shape not in ((), (3,)) or np.isnan(k).any() or not (k > 0).all():
            raise ValueError(f"stiffness_nm_rad = {self.stiffness_nm_rad!r}: must be > 0")

    def holding_torques_nm(self, joints_rad: np.ndarray) -> np.ndarray:
        """Torques [N m] that hold the arm at rest at `joints_rad` [rad], shape (3,) ->
        (3,) (positive turns theta positive, the link down)."""
        q = np.asarray(joints_rad, dtype=float)
        zero = np.zeros_like(q)
        return np.asarray(inverse_dynamics_joints(self.robot, self.mass, q, zero, zero))

    def offset_rad(self, joints_rad: np.ndarray) -> np.ndarray:
        """The predicted sag tau_g / k [rad] at `joints_rad` [rad], shape (3,): added to the
        goal it puts the arm at rest on the goal. NaN where the pose has no kinematics."""
        return self.holding_torques_nm(joints_rad) / self.stiffness_nm_rad


def loop_stiffness_nm_rad(gains: Sequence[PositionGains]) -> np.ndarray:
    """Per joint (N,) [N m/rad], the stiffness the offset divides by under `gains` (N):
    the P loop's (`position_stiffness_nm_rad`), or inf where the loop has an integral (it
    removes the sag itself, so an offset would become the error at rest)."""
    return np.array([math.inf if g.i > 0 else position_stiffness_nm_rad(g.p) for g in gains])


def gravity_offset(
    robot: object, payload_kg: float = 0.0, wrist: bool = False, p_gain: int | None = None
) -> GravityOffset:
    """The offset for `robot` with the thesis masses, `payload_kg` [kg] on the platform and,
    with `wrist`, an XM430 wrist on it; `p_gain` the Position P Gain (None: factory 800).

    Raises ValueError for a robot that is not a rotary Delta (a linear Delta's rails need
    their own dynamics model).
    """
    if not isinstance(robot, RotaryDelta):
        raise ValueError("control.gravity_compensation: only rotary Deltas have a gravity model")
    mass = THESIS_MASS.with_wrist() if wrist else THESIS_MASS
    mass = mass.with_payload(payload_kg)
    stiffness = position_stiffness_nm_rad(PositionGains().p if p_gain is None else p_gain)
    return GravityOffset(robot, mass, stiffness)
