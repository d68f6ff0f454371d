"""The Delta's mass model for the simulator, and its gravity torques (Lagrangian statics).

Defaults are the thesis's components (ch. 4.2): a 29 g nylon upper link, two CFRP rods of
10.5 g each (with their ball joints) per leg, a 25 g platform and 82 g servos on the base.
The lower link of each leg is treated as one uniform rod of both rods' mass (the thesis's
model, ch. 3.2); the upper link as a uniform rod about the motor axis plus the servo's
rotor inertia reflected through the gearbox.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from kinematics import RotaryDelta
from kinematics.dynamics import WRIST_XM430, MassModel, WristMasses

__all__ = ["WRIST_XM430", "DeltaMasses", "WristMasses", "gravity_torques"]

GRAVITY_M_S2 = 9.81


@dataclass(frozen=True)
class DeltaMasses:
    """Masses [kg] and inertias [kg m^2] of the moving parts; all configurable.

    upper_kg: one upper link; upper_inertia_kgm2: its inertia about the motor axis (None:
    uniform rod, m L^2 / 3); rod_kg: one rod with its two ball joints; rods_per_leg: 2 for
    a parallelogram; platform_kg: the moving platform; payload_kg: tool and load on the
    platform (the thesis designs for up to 0.2 kg); servo_kg: one servo (on the base, so it
    adds nothing to the arm's dynamics); rotor_inertia_kgm2: the motor's rotor about its own
    axis, reflected to the output as rotor * gear_ratio^2 (ROBOTIS does not publish it;
    1.0e-7 kg m^2 is the estimate kinematics.dynamics.THESIS_MASS uses, 4.5e-3 kg m^2 at
    the output, uncertain by x3); wrist_servo_kg, wrist_kg, wrist_inertia_kgm2: a wrist
    on the platform (`with_wrist`, `WRIST_XM430`): its servo's case, and its turning part
    with its inertia about the platform's z axis [kg m^2]; 0 without a wrist.
    """

    upper_kg: float = 0.029
    upper_inertia_kgm2: float | None = None
    rod_kg: float = 0.0105
    rods_per_leg: int = 2
    platform_kg: float = 0.025
    payload_kg: float = 0.0
    servo_kg: float = 0.082
    rotor_inertia_kgm2: float = 1.0e-7
    gear_ratio: float = 212.6
    wrist_servo_kg: float = 0.0
    wrist_kg: float = 0.0
    wrist_inertia_kgm2: float = 0.0

    def __post_init__(self) -> None:
        names = ("upper_kg", "rod_kg", "platform_kg", "payload_kg", "servo_kg")
        wrist = ("wrist_servo_kg", "wrist_kg", "wrist_inertia_kgm2")
        for name in names + wrist:
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} = {value!r}: must be finite and >= 0")
        if self.platform_kg + self.payload_kg <= 0 or self.rods_per_leg < 1:
            raise ValueError("the platform needs a mass and each leg at least one rod")

    @property
    def lower_kg(self) -> float:
        """Mass of one leg's lower link (all its rods) [kg]."""
        return self.rod_kg * self.rods_per_leg

    @property
    def has_wrist(self) -> bool:
        """A wrist servo is on the platform (its mass is part of the model)."""
        return self.wrist_servo_kg > 0 or self.wrist_kg > 0

    @property
    def platform_total_kg(self) -> float:
        """Everything the platform carries [kg]: platform, payload, and with a wrist its
        servo (fixed to the platform) and its turning part (horn and tool)."""
        return self.platform_kg + self.payload_kg + self.wrist_servo_kg + self.wrist_kg

    def with_wrist(
        self,
        servo_kg: float | None = None,
        turning_kg: float | None = None,
        turning_inertia_kgm2: float | None = None,
    ) -> DeltaMasses:
        """These masses with a wrist on the platform (defaults: `WRIST_XM430`)."""
        return replace(
            self,
            wrist_servo_kg=WRIST_XM430.servo_kg if servo_kg is None else servo_kg,
            wrist_kg=WRIST_XM430.turning_kg if turning_kg is None else turning_kg,
            wrist_inertia_kgm2=(
                WRIST_XM430.turning_inertia_kgm2
                if turning_inertia_kgm2 is None
                else turning_inertia_kgm2
            ),
        )

    def upper_inertia(self, L: float) -> float:
        """Upper link inertia about the motor axis [kg m^2] for link length `L` [m]."""
        if self.upper_inertia_kgm2 is not None:
            return self.upper_inertia_kgm2
        return self.upper_kg * L * L / 3.0

    @property
    def armature_kgm2(self) -> float:
        """The rotor's inertia seen at the output shaft [kg m^2]."""
        return self.rotor_inertia_kgm2 * self.gear_ratio**2

    def mass_model(self, L: float) -> MassModel:
        """The same masses as kinematics.dynamics.MassModel, for upper link length `L` [m]."""
        return MassModel(
            platform_kg=self.platform_total_kg,
            upper_kg=self.upper_kg,
            upper_inertia_kgm2=self.upper_inertia(L) + self.armature_kgm2,
            lower_kg=self.lower_kg,
        )


THESIS_MASSES = DeltaMasses()


def gravity_torques(
    robot: RotaryDelta,
    masses: DeltaMasses,
    joints: np.ndarray,
    gravity: np.ndarray | tuple[float, float, float] = (0.0, 0.0, -GRAVITY_M_S2),
) -> np.ndarray:
    """Motor torques [N m] that hold the arm at rest at `joints` [rad], shape (3,).

    Virtual work: the platform, payload and half of each lower link act at the platform
    centre through the Jacobian (tau = -J^T F); each upper link's own weight at L/2 and the
    other half of its lower link at the knee act on its motor directly. Positive torque
    turns theta positive (upper link down). `gravity`: acceleration in the base frame.
    """
    g = np.asarray(gravity, dtype=float)
    q = np.asarray(joints, dtype=float)
    J = robot.jacobian(q)  # dP/dtheta, (3, 3)
    platform_weight = (masses.platform_total_kg + 1.5 * masses.lower_kg) * g
    taus = -(J.T @ platform_weight)
    for i in range(3):
        # d(knee)/d(theta_i) and d(centre of the upper link)/d(theta_i) in the base frame
        alpha = 2.0 * math.pi * i / 3.0
        dknee = robot.L * np.array(
            [-math.cos(alpha) * math.sin(q[i]), -math.sin(alpha) * math.sin(q[i]), -math.cos(q[i])]
        )
        link_weight = (0.5 * masses.upper_kg + 0.5 * masses.lower_kg) * g
        taus[i] -= dknee @ link_weight
    return taus
